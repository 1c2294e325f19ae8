// `layersnet generate` end to end: a tiny sequence twice with the same seed gives identical
// arrays, a second run keeps existing sequences (resume), every file passes the D-LAYERS-H5
// checker, and the garment templates pass their geometric checks. Blender-dependent tests
// are skipped when Blender is not installed.
#include "dataset/sequence.h"

#include <gtest/gtest.h>

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

TEST(GenerateGarments, TemplatesHavePanelsMetricUvAndLayerGap) {
  if (run("/usr/bin/python3 -c 'import numpy' > /dev/null 2>&1") != 0) GTEST_SKIP() << "no numpy";
  EXPECT_EQ(run("/usr/bin/python3 " + kSource + "/tests/generate/test_garments.py"), 0);
}

TEST(GenerateMotionWind, ProceduralOverlaysAndHorizontalWind) {
  if (run("/usr/bin/python3 -c 'import numpy' > /dev/null 2>&1") != 0) GTEST_SKIP() << "no numpy";
  EXPECT_EQ(run("/usr/bin/python3 " + kSource + "/tests/generate/test_motion_wind.py"), 0);
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
