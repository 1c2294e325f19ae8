// `layersnet generate` end to end: a tiny sequence twice with the same seed gives identical
// arrays, a second run keeps existing sequences (resume), every file passes the D-LAYERS-H5
// checker, and the garment templates pass their geometric checks. Blender-dependent tests
// are skipped when Blender is not installed.
#include "dataset/sequence.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

namespace fs = std::filesystem;

namespace {

const std::string kSource = LAYERSNET_SOURCE_DIR;
const std::string kBinary = LAYERSNET_BINARY;
const std::string kChecker = kSource + "/dataset/check_dlayers_h5.py";

bool have_blender() { return std::system("blender --version > /dev/null 2>&1") == 0; }

int run(const std::string& cmd) { return std::system(cmd.c_str()); }

std::string slurp(const fs::path& p) {
  std::ifstream in(p);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

fs::path dir(const char* name) { return fs::temp_directory_path() / ("layersnet_test_generate_" + std::string(name)); }

std::string generate_cmd(const fs::path& out) {
  return kBinary + " generate --recipe " + kSource + "/generate/recipes/tiny.json --count 1 --frames 6 --seed 5 --out " +
         out.string() + " > " + out.string() + ".stdout 2>&1";
}

// One test (CTest runs each test in its own process): two runs with the same seed, a resume
// run, and the checker; about 30 s on 2 cores.
TEST(GenerateTiny, DeterministicResumableAndValid) {
  if (!have_blender()) GTEST_SKIP() << "blender not installed";
  for (const char* n : {"a", "b"}) {
    fs::remove_all(dir(n));
    ASSERT_EQ(run(generate_cmd(dir(n))), 0) << slurp(dir(n).string() + ".stdout");
    ASSERT_TRUE(fs::exists(dir(n) / "00000.h5")) << slurp(dir(n) / "generate_report.md");
  }
  // Same seed -> identical arrays and attributes (except wall-clock timings).
  EXPECT_EQ(run("/usr/bin/python3 " + kSource + "/tests/generate/compare_h5.py " + (dir("a") / "00000.h5").string() +
                " " + (dir("b") / "00000.h5").string()),
            0);
  const std::string manifest = slurp(dir("a") / "dataset.json");
  EXPECT_NE(manifest.find("\"train\""), std::string::npos);
  EXPECT_NE(manifest.find("\"00000\""), std::string::npos);
  EXPECT_NE(manifest.find("\"subsets\""), std::string::npos);
  const std::string report = slurp(dir("a") / "generate_report.json");
  EXPECT_NE(report.find("blender_s_per_frame"), std::string::npos);
  EXPECT_NE(report.find("inside_body_share"), std::string::npos);
  // Resume: the accepted sequence is kept, not simulated again.
  const auto before = fs::last_write_time(dir("a") / "00000.h5");
  ASSERT_EQ(run(generate_cmd(dir("a"))), 0);
  EXPECT_NE(slurp(dir("a").string() + ".stdout").find("kept (resume)"), std::string::npos);
  EXPECT_EQ(fs::last_write_time(dir("a") / "00000.h5"), before);
  EXPECT_EQ(run("/usr/bin/python3 " + kChecker + " " + dir("a").string()), 0);
  // Every garment's pinned top ring is stored.
  const layersnet::dataset::Sequence seq = layersnet::dataset::read_sequence((dir("a") / "00000.h5").string());
  for (const layersnet::dataset::GarmentMesh& g : seq.info.garments) {
    EXPECT_GE(g.num_pinned(), 3) << g.name;
    EXPECT_LT(g.num_pinned(), g.num_vertices / 2) << g.name;
  }
}

// The pinned square of generate/README.md ("The wind"): still without wind, a small angle at
// strength 20, and blown out towards the horizontal at strength 400 (82 degrees measured, mean of
// the last 30 of 120 frames, flapping about it).
TEST(GenerateWind, PinnedSquareHangsAtTheMeasuredAngles) {
  if (!have_blender()) GTEST_SKIP() << "blender not installed";
  auto angle = [](double strength, int frames) {
    const fs::path out = fs::temp_directory_path() / ("layersnet_test_wind_square_" + std::to_string(static_cast<int>(strength)) + ".json");
    fs::remove(out);
    const std::string cmd = "blender -b --factory-startup -t 1 --python " + kSource + "/generate/wind_square.py -- --strength " +
                            std::to_string(strength) + " --frames " + std::to_string(frames) + " --average 30 --out " +
                            out.string() + " > " + out.string() + ".log 2>&1";
    if (run(cmd) != 0 || !fs::exists(out)) return -1.0;
    const std::string text = slurp(out);
    const auto at = text.find("\"angle_deg\":");
    return at == std::string::npos ? -1.0 : std::stod(text.substr(at + 12));
  };
  const double calm = angle(0, 40), light = angle(20, 120), strong = angle(400, 120);
  EXPECT_GE(calm, 0.0);
  EXPECT_LT(calm, 1.0);
  EXPECT_GT(light, 10.0);
  EXPECT_LT(light, 25.0);
  EXPECT_GT(strong, 60.0);
  EXPECT_LT(strong, 110.0);
}

// The large recipe's features on two short sequences made by two Blender processes at once:
// procedural overlays, a long skirt under a long coat, horizontal wind.
TEST(GenerateLargeFeatures, TwoJobsProceduralLongGarmentsHorizontalWind) {
  if (!have_blender()) GTEST_SKIP() << "blender not installed";
  const fs::path out = dir("large_features");
  fs::remove_all(out);
  fs::create_directories(out);
  const fs::path recipe = out.string() + ".recipe.json";
  // Gates wide open: this checks the features, not the quality of a 12-frame sequence.
  std::ofstream(recipe) << R"({"count": 2, "seed": 3, "val_fraction": 0.0, "test_fraction": 0.0, "max_attempts": 1,
    "gates": {"max_inside_body_share": 1.0, "max_outer_inside_inner_share": 1.0, "max_edge_stretch": 1000.0, "max_p99_edge_stretch": 1000.0},
    "scene": {"frames": 12, "rest_frames": 3, "ramp_frames": 4,
              "procedural": {"probability": 1.0, "hop_probability": 1.0, "arm_swing_probability": 1.0},
              "inner_kinds": ["skirt_long", "dress_long"], "outer_kinds": ["coat_long"],
              "wind_direction": "horizontal", "wind_segments": [2, 3], "wind_calm_probability": 0.0,
              "wind_windy_probability": 1.0}})";
  ASSERT_EQ(run(kBinary + " generate --recipe " + recipe.string() + " --jobs 2 --threads 1 --out " + out.string() + " > " +
                out.string() + ".stdout 2>&1"),
            0)
      << slurp(out.string() + ".stdout");
  for (const char* id : {"00000", "00001"}) {
    ASSERT_TRUE(fs::exists(out / (std::string(id) + ".h5"))) << slurp(out / "generate_report.md");
    const std::string report = slurp(out / "reports" / (std::string(id) + ".json"));
    EXPECT_NE(report.find("\"motion\": \"procedural\""), std::string::npos) << id;
    EXPECT_NE(report.find("coat_long"), std::string::npos) << id;
  }
  // Wind directions within 30 degrees of the ground plane: the field's z axis rotated by the
  // stored quaternion (w, x, y, z) has |z| <= sin 30 (frames before the first pivot: no wind).
  const layersnet::dataset::Sequence seq = layersnet::dataset::read_sequence((out / "00000.h5").string());
  const auto& rot = seq.info.wind_rotation;
  ASSERT_GT(rot.rows(), 0);
  double strongest = 0.0;
  for (Eigen::Index f = 0; f < rot.rows(); ++f) {
    const double x = rot(f, 1), y = rot(f, 2);
    if (seq.info.wind_strength(f) <= 0) continue;
    EXPECT_LE(std::abs(1.0 - 2.0 * (x * x + y * y)), 0.5 + 1e-5) << "frame " << f;
    strongest = std::max<double>(strongest, seq.info.wind_strength(f));
  }
  EXPECT_GT(strongest, 250.0);
  EXPECT_EQ(run("/usr/bin/python3 " + kChecker + " " + out.string()), 0);
}

TEST(GenerateGarments, TemplatesHavePanelsMetricUvAndLayerGap) {
  if (run("/usr/bin/python3 -c 'import numpy' > /dev/null 2>&1") != 0) GTEST_SKIP() << "no numpy";
  EXPECT_EQ(run("/usr/bin/python3 " + kSource + "/tests/generate/test_garments.py"), 0);
}

TEST(GenerateMotionWind, ProceduralOverlaysAndHorizontalWind) {
  if (run("/usr/bin/python3 -c 'import numpy' > /dev/null 2>&1") != 0) GTEST_SKIP() << "no numpy";
  EXPECT_EQ(run("/usr/bin/python3 " + kSource + "/tests/generate/test_motion_wind.py"), 0);
}

TEST(GenerateCloth, SceneKeyClothIsValidatedAndSkinnedRecipeIsAllTrain) {
  if (run("/usr/bin/python3 -c 'import numpy' > /dev/null 2>&1") != 0) GTEST_SKIP() << "no numpy";
  EXPECT_EQ(run("/usr/bin/python3 " + kSource + "/tests/generate/test_cloth_mode.py"), 0);
}

TEST(GenerateGarments, HeldOutKindsOnlyWhereTheRecipeListsTheSplit) {
  if (run("/usr/bin/python3 -c 'import numpy' > /dev/null 2>&1") != 0) GTEST_SKIP() << "no numpy";
  EXPECT_EQ(run("/usr/bin/python3 " + kSource + "/tests/generate/test_heldout_outfits.py"), 0);
}

// About 15 s: a 12-frame "surface" sequence and its "blender" twin.
TEST(GenerateCloth, SurfaceCarriesGarmentsOnTheSameBody) {
  if (!have_blender()) GTEST_SKIP() << "blender not installed";
  if (run("/usr/bin/python3 -c 'import h5py, numpy' > /dev/null 2>&1") != 0) GTEST_SKIP() << "no h5py/numpy";
  EXPECT_EQ(run("/usr/bin/python3 " + kSource + "/tests/generate/test_cloth_mode.py --blender"), 0);
}

TEST(GenerateGarments, OlderFilesGetTheGeneratorsPins) {
  if (run("/usr/bin/python3 -c 'import h5py, numpy' > /dev/null 2>&1") != 0) GTEST_SKIP() << "no h5py/numpy";
  EXPECT_EQ(run("/usr/bin/python3 " + kSource + "/tests/generate/test_add_pins.py"), 0);
}

TEST(GenerateRecipes, MediumMotionBlocksAreDisjointAndFit) {
  if (run("/usr/bin/python3 -c 'import numpy' > /dev/null 2>&1") != 0) GTEST_SKIP() << "no numpy";
  if (!fs::exists("/usr/share/assimp/models/BVH/Boxing_Toes.bvh")) GTEST_SKIP() << "assimp-testmodels not installed";
  EXPECT_EQ(run("/usr/bin/python3 " + kSource + "/tests/generate/test_motion_blocks.py"), 0);
}

TEST(GenerateConvert, MockDLayersReleaseConvertsToValidFiles) {
  if (run("/usr/bin/python3 -c 'import h5py, numpy' > /dev/null 2>&1") != 0) GTEST_SKIP() << "no h5py/numpy";
  EXPECT_EQ(run("/usr/bin/python3 " + kSource + "/tests/generate/test_convert.py"), 0);
}

TEST(GenerateCli, MissingRecipeIsAnErrorNamingTheFile) {
  const fs::path out = fs::temp_directory_path() / "layersnet_test_generate_badrecipe";
  const std::string log = out.string() + ".stdout";
  EXPECT_NE(run(kBinary + " generate --recipe /nonexistent/recipe.json --out " + out.string() + " > " + log + " 2>&1"), 0);
  EXPECT_NE(slurp(log).find("/nonexistent/recipe.json"), std::string::npos);
}

}  // namespace
