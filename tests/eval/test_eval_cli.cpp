// `layersnet eval` and `layersnet export` end to end: a freshly initialised tiny model
// (configs/tiny.toml) in a checkpoint, on a tiny synthetic data set.
#include "dataset/h5.h"
#include "dataset/sha256.h"
#include "dataset/stats.h"
#include "dataset/synthetic.h"
#include "eval/evaluate.h"
#include "eval/render.h"
#include "eval/rollout.h"
#include "model/params_layout.h"
#include "run/checkpoint.h"
#include "run/config.h"

#include "tests/eval/cli_test_util.h"

#include "dataset/sha256.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <array>
#include <cstdlib>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>

namespace layersnet::eval {
namespace {

namespace fs = std::filesystem;

std::string run(const std::string& args, int* code) { return cli_test::run_cli(args, code); }
using cli_test::slurp;

class EvalCli : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    root_ = fs::temp_directory_path() / ("layersnet_eval_test_" + std::to_string(::getpid()));
    fs::remove_all(root_);
    cli_test::write_tiny_data_and_checkpoint(root_, 2, 0, 2, /*wind=*/true);
    // A second variant without statistics in the checkpoint (falls back to stats.h5).
    Config v = load_config({std::string(LAYERSNET_SOURCE_DIR) + "/configs/tiny.toml"});
    v.data.dataset = (root_ / "data").string();
    v.model.rotation_equivalent = false;
    ad::ParamStore<float> pv;
    model::register_params(pv, v.model);
    model::init_params(pv, v.model, 8);
    Checkpoint cv;
    cv.config_toml = to_toml(v);
    write_checkpoint((root_ / "vanilla.h5").string(), pv, cv);
  }
  // LAYERSNET_EVAL_TEST_KEEP=1 keeps the folder (data set, checkpoints, reports) to look at.
  static void TearDownTestSuite() {
    if (!std::getenv("LAYERSNET_EVAL_TEST_KEEP")) fs::remove_all(root_);
  }
  // The report of `eval` on the tiny model, 3 frames, with `extra` options, written to root_/name.
  static nlohmann::json eval_tiny(const std::string& extra, const std::string& name) {
    int code = 0;
    const fs::path out = root_ / name;
    const std::string text = run("eval --checkpoint " + (root_ / "tiny.h5").string() +
                                     " --frames 3 --speed-frames 1 --out " + out.string() + extra,
                                 &code);
    EXPECT_EQ(code, 0) << text;
    return nlohmann::json::parse(slurp(out / "eval.json"));
  }
  // Each method's mean error (mm), in the report's order.
  static std::vector<double> mean_errors(const nlohmann::json& report) {
    std::vector<double> e;
    for (const auto& m : report["methods"]) e.push_back(m["summary"]["error_mm"]["mean"].get<double>());
    return e;
  }
  static fs::path root_;
};
fs::path EvalCli::root_;

TEST_F(EvalCli, EvalWritesReportsAndPrintsTheSummaryTable) {
  int code = 0;
  const fs::path out = root_ / "eval";
  const std::string text = run("eval --checkpoint " + (root_ / "tiny.h5").string() + " --checkpoint " +
                                   (root_ / "vanilla.h5").string() + " --frames 3 --speed-frames 2 --out " +
                                   out.string(),
                               &code);
  ASSERT_EQ(code, 0) << text;
  EXPECT_NE(text.find("constant velocity"), std::string::npos) << text;
  EXPECT_NE(text.find("follow the body"), std::string::npos) << text;
  EXPECT_NE(text.find("ms/f 1t"), std::string::npos) << text;
  const auto j = nlohmann::json::parse(slurp(out / "eval.json"));
  EXPECT_NE(text.find("skinned to the body"), std::string::npos) << text;
  EXPECT_NE(text.find("one physics step"), std::string::npos) << text;
  EXPECT_EQ(j["physics_step_baseline"], "defaults");  // neither model corrects a physics step
  // 2 models, 5 baselines (bare: the models run without the constraints), ground truth.
  ASSERT_EQ(j["methods"].size(), 8u);
  EXPECT_EQ(j["split"], "test");
  for (const auto& m : j["methods"]) {
    ASSERT_EQ(m["sequences"].size(), 2u) << m["name"];
    EXPECT_EQ(m["sequences"][0]["error_curve_mm"].size(), 3u);
    EXPECT_GE(m["summary"]["h_collision_percent"]["mean"].get<double>(), 0.0);
    EXPECT_GE(m["summary"]["strain_mean_percent"]["mean"].get<double>(), 0.0) << m["name"];
    EXPECT_EQ(m["summary"]["strain_p99_curve_percent"].size(), 3u) << m["name"];
    EXPECT_EQ(m["sequences"][0]["strain_p99_curve"].size(), 3u) << m["name"];
  }
  const auto& gt = j["methods"][7];
  EXPECT_EQ(gt["kind"], "ground truth");
  EXPECT_EQ(gt["summary"]["error_mm"]["mean"].get<double>(), 0.0);
  EXPECT_GT(gt["summary"]["strain_p99_percent"]["mean"].get<double>(), 0.0);  // the synthetic cloth ripples
  EXPECT_NE(text.find("strain99%"), std::string::npos) << text;
  EXPECT_NE(text.find("crumple"), std::string::npos) << text;
  EXPECT_EQ(j["methods"][0]["kind"], "model");
  EXPECT_GT(j["methods"][0]["ms_per_frame_1thread"].get<double>(), 0.0);
  EXPECT_GT(j["methods"][1]["ms_per_frame_2threads"].get<double>(), 0.0);
  // mm = scene units / scale * 1000 (synthetic scale 10).
  const auto& s0 = j["methods"][0]["sequences"][0];
  EXPECT_NEAR(s0["error_mm"].get<double>(), s0["error_units"].get<double>() * 100.0, 1e-9);
  const std::string md = slurp(out / "eval.md");
  EXPECT_NE(md.find("Per garment type"), std::string::npos);
  EXPECT_NE(md.find("| T | T+W | L | L+W |"), std::string::npos);
  EXPECT_NE(md.find("## Edge strain"), std::string::npos);
  if (std::system("command -v gnuplot >/dev/null 2>&1") == 0) {
    EXPECT_TRUE(fs::exists(out / "curve.png"));
    EXPECT_TRUE(fs::exists(out / "speed.png"));
    EXPECT_TRUE(fs::exists(out / "strain.png"));
    EXPECT_TRUE(fs::exists(out / "crumple.png"));
  }
  // The report folder holds reports only: plot data and scripts are removed.
  for (const char* leftover : {"curve.dat", "strain.dat", "crumple.dat", "speed.dat", "plots.gp", "gnuplot.log"})
    EXPECT_FALSE(fs::exists(out / leftover)) << leftover;
  // Provenance: the checkpoint's and the manifest's SHA-256.
  EXPECT_EQ(j["methods"][0]["checkpoint_sha256"].get<std::string>().size(), 64u);
  EXPECT_EQ(j["methods"][0]["checkpoint_sha256"], io::sha256_file((root_ / "tiny.h5").string()));
  EXPECT_NE(j["methods"][0]["checkpoint_sha256"], j["methods"][1]["checkpoint_sha256"]);
  EXPECT_EQ(j["dataset_manifest_sha256"].get<std::string>().size(), 64u);
  // Crumple and the free-cloth split for every method, the ground truth too.
  for (const auto& m : j["methods"]) {
    EXPECT_EQ(m["summary"]["dihedral_curve_deg"].size(), 3u) << m["name"];
    EXPECT_GT(m["summary"]["dihedral_mean_deg"]["mean"].get<double>(), 0.0) << m["name"];
    EXPECT_TRUE(m["summary"].contains("free_cloth_mm")) << m["name"];
  }
  // Each model against each bare baseline, one best.
  ASSERT_EQ(j["comparisons"].size(), 10u);
  int best = 0;
  for (const auto& c : j["comparisons"]) {
    EXPECT_FALSE(c["post_processed"].get<bool>());
    EXPECT_EQ(c["per_sequence"].size(), 2u);
    best += c["best_baseline"].get<bool>();
  }
  EXPECT_EQ(best, 2);
  EXPECT_NE(md.find("against the baselines under the same post-processing"), std::string::npos);
  EXPECT_NE(md.find("## Crumple and long rollouts"), std::string::npos);
}

// With the constraints on, every baseline runs bare and post-processed, and each model row
// meets the baselines with its own post-processing.
TEST_F(EvalCli, BaselinesGetTheModelsPostProcessing) {
  int code = 0;
  const fs::path out = root_ / "eval_post";
  const std::string text = run("eval --checkpoint " + (root_ / "tiny.h5").string() +
                                   " --constraints off,on --frames 3 --speed-frames 1 --out " + out.string(),
                               &code);
  ASSERT_EQ(code, 0) << text;
  const auto j = nlohmann::json::parse(slurp(out / "eval.json"));
  ASSERT_EQ(j["methods"].size(), 13u);  // 2 model rows, 10 baselines, ground truth
  int post = 0;
  for (const auto& m : j["methods"])
    if (m["kind"] == "baseline" && m["post_processed"].get<bool>()) {
      ++post;
      EXPECT_EQ(m["name"].get<std::string>().rfind("[constrained] ", 0), 0u) << m["name"];
    }
  EXPECT_EQ(post, 5);
  for (const auto& c : j["comparisons"])
    EXPECT_EQ(c["model"].get<std::string>().rfind("[constrained] ", 0) == 0, c["post_processed"].get<bool>()) << c;
  EXPECT_EQ(j["comparisons"].size(), 10u);
  EXPECT_EQ(j["post_processing"]["strain_limit"].get<double>(), 0.05);
}

// The step baseline is the evaluated physics-base model's own step: a zero-output model on a
// softer step scores exactly what the baseline scores, and the reports name where the step came
// from. Without such a model the baseline keeps the defaults (the test above: "defaults").
TEST_F(EvalCli, PhysicsStepBaselineIsThePhysicsModelsOwnStep) {
  const fs::path soft = root_ / "soft_step.h5";  // untrained: the model predicts its step
  cli_test::write_tiny_checkpoint(soft, dataset::read_stats((root_ / "data" / "stats.h5").string()),
                                  (root_ / "data").string(),
                                  {"model.velocity_base=physics", "model.physics_step_bending=0.25"});
  int code = 0;
  const fs::path out = root_ / "eval_soft_step";
  const std::string text = run("eval --checkpoint " + (root_ / "tiny.h5").string() + " --checkpoint " +
                                   soft.string() + " --frames 3 --speed-frames 1 --out " + out.string(),
                               &code);
  ASSERT_EQ(code, 0) << text;
  EXPECT_NE(text.find("baseline 'one physics step' is the step of " + soft.string()), std::string::npos) << text;
  const auto j = nlohmann::json::parse(slurp(out / "eval.json"));
  EXPECT_EQ(j["physics_step_baseline"], soft.string());
  // (the step baseline's error, the zero-output model's) in an eval.json, mm; -1 where missing.
  const auto step_and_model = [&](const nlohmann::json& report) {
    std::pair<double, double> e{-1, -1};
    for (const auto& m : report["methods"]) {
      if (m["name"] == "one physics step") e.first = m["summary"]["error_mm"]["mean"].get<double>();
      if (m["checkpoint"] == soft.string()) e.second = m["summary"]["error_mm"]["mean"].get<double>();
    }
    return e;
  };
  const auto [step_error, zero_model] = step_and_model(j);
  EXPECT_GT(step_error, 0.0);
  EXPECT_NEAR(zero_model, step_error, 1e-3 * step_error);
  EXPECT_NE(slurp(out / "eval.md").find("the step of `" + soft.string() + "`"), std::string::npos);

  // --set model.physics_step_cg_iterations moves the model's step and the baseline together.
  const fs::path short_out = root_ / "eval_soft_step_cg2";
  const std::string short_text = run("eval --checkpoint " + soft.string() + " --frames 3 --speed-frames 1 " +
                                         "--set model.physics_step_cg_iterations=2 --out " + short_out.string(),
                                     &code);
  ASSERT_EQ(code, 0) << short_text;
  const auto [short_step, short_model] = step_and_model(nlohmann::json::parse(slurp(short_out / "eval.json")));
  EXPECT_NEAR(short_model, short_step, 1e-3 * short_step);
  EXPECT_GT(std::abs(short_step - step_error), 1e-3 * step_error) << "two iterations solve as far as sixty";
}

// --mirror evaluates the sequences' mirror images: the model-free baselines and the physics step
// are symmetric under a mirror, so their errors stay (to rounding); the network is not, so its
// rollouts move. The reports say which sequences were evaluated.
TEST_F(EvalCli, MirrorLeavesTheSymmetricBaselinesAndMovesTheNetwork) {
  const auto errors = [&](const std::string& extra, const std::string& name) {
    const auto j = eval_tiny(extra, name);
    return std::make_pair(mean_errors(j), j["mirror"].get<bool>());
  };
  const auto [files, mirror_off] = errors("", "eval_files");
  const auto [images, mirror_on] = errors(" --mirror", "eval_mirror");
  EXPECT_FALSE(mirror_off);
  EXPECT_TRUE(mirror_on);
  ASSERT_EQ(files.size(), 7u);  // model, 5 baselines, ground truth
  ASSERT_EQ(images.size(), 7u);
  EXPECT_GT(std::abs(files[0] - images[0]), 1e-4 * files[0]);  // the network is not mirror-symmetric
  for (std::size_t k = 1; k < 7; ++k) EXPECT_NEAR(images[k], files[k], 1e-4 * files[k] + 1e-9) << k;
  EXPECT_NE(slurp(root_ / "eval_mirror" / "eval.md").find("mirror images"), std::string::npos);
  int code = 0;
  const std::string refused = run("eval --checkpoint " + (root_ / "tiny.h5").string() + " --frames 3 --mirror --wind-scale 0 --wind-twins " +
                                      (root_ / "no_twins").string() + " --out " + (root_ / "eval_refused").string(),
                                  &code);
  EXPECT_EQ(code, 1) << refused;
  EXPECT_NE(refused.find("mirror images"), std::string::npos) << refused;
}

// --wind-scale changes the wind only as the models see it: the model's rollouts move, the
// baselines and the ground truth they are scored against do not, and the reports say so and how
// far the change moved the model's cloth.
TEST_F(EvalCli, WindScaleChangesWhatTheModelSeesNotTheTruth) {
  const auto errors = [&](const std::string& extra, const std::string& name) {
    const auto j = eval_tiny(extra, name);
    return std::make_pair(mean_errors(j), j["wind_scale"].get<double>());
  };
  const auto [data_wind, scale_1] = errors("", "eval_wind_1");
  const auto [calm, scale_0] = errors(" --wind-scale 0", "eval_wind_0");
  EXPECT_EQ(scale_1, 1.0);
  EXPECT_EQ(scale_0, 0.0);
  ASSERT_EQ(data_wind.size(), 7u);  // model, 5 baselines, ground truth
  ASSERT_EQ(calm.size(), 7u);
  EXPECT_NE(data_wind[0], calm[0]);  // the model reads the wind
  for (std::size_t k = 1; k < 7; ++k) EXPECT_EQ(data_wind[k], calm[k]) << k;
  EXPECT_NE(slurp(root_ / "eval_wind_0" / "eval.md").find("wind strengths x 0"), std::string::npos);
  const auto moved = [&](const std::string& name) {
    std::vector<nlohmann::json> out;
    const auto report = nlohmann::json::parse(slurp(root_ / name / "eval.json"));
    for (const auto& m : report["methods"])
      out.push_back(m["summary"].value("wind_moved_mm", nlohmann::json()));
    return out;
  };
  const auto moved_0 = moved("eval_wind_0"), moved_1 = moved("eval_wind_1");
  ASSERT_FALSE(moved_0[0].is_null());  // the model, on the sequences with wind
  EXPECT_GT(moved_0[0]["sequences"].get<int>(), 0);
  EXPECT_GT(moved_0[0]["mean"].get<double>(), 0.0);
  for (std::size_t k = 1; k < 7; ++k) EXPECT_TRUE(moved_0[k].is_null()) << k;  // the data's wind throughout
  for (const auto& m : moved_1) EXPECT_TRUE(m.is_null());
  EXPECT_NE(slurp(root_ / "eval_wind_0" / "eval.md").find("What the wind change moves"), std::string::npos);
}

// Twins of the test sequences whose cloth sits 0.01 units per frame index along x from the data's,
// as if the calm wind had left Blender's cloth there: the report sets each model's wind response
// against it.
TEST_F(EvalCli, WindTwinsSetEachModelsWindResponseAgainstBlenders) {
  const fs::path twins = root_ / "twins";
  fs::create_directories(twins);
  const dataset::DatasetManifest manifest = dataset::read_manifest((root_ / "data").string());
  for (const std::string& id : manifest.split("test")) {
    dataset::Sequence seq = dataset::read_sequence(manifest.sequence_path(id));
    for (int g = 0; g < seq.info.num_garments(); ++g)
      for (int t = seq.frames.first; t < seq.frames.first + seq.frames.count; ++t)
        seq.frames.garments[g]
            .middleRows(static_cast<Eigen::Index>(t - seq.frames.first) * seq.info.garments[g].num_vertices,
                        seq.info.garments[g].num_vertices)
            .col(0)
            .array() += 0.01f * static_cast<float>(t);
    dataset::write_sequence((twins / fs::path(manifest.sequence_path(id)).filename()).string(), seq);
  }
  std::ofstream(twins / "scene.json") << R"({"wind_scale": 0.0, "seed": 1})";
  const auto report = [&](const std::string& extra, const std::string& name, int* code) {
    const fs::path out = root_ / name;
    const std::string text = run("eval --checkpoint " + (root_ / "tiny.h5").string() +
                                     " --frames 3 --speed-frames 1 --out " + out.string() + extra, code);
    return std::make_pair(text, *code == 0 ? nlohmann::json::parse(slurp(out / "eval.json")) : nlohmann::json());
  };
  int code = 0;
  const auto [text, calm] = report(" --wind-scale 0 --wind-twins " + twins.string(), "eval_twins", &code);
  ASSERT_EQ(code, 0) << text;
  const auto [text_1, data_wind] = report("", "eval_twins_wind_1", &code);
  ASSERT_EQ(code, 0) << text_1;
  EXPECT_EQ(calm["wind_twins"], twins.string());
  const auto& model = calm["methods"][0];
  ASSERT_TRUE(model["summary"].contains("wind_share")) << model["summary"].dump();
  int windy = 0;
  for (std::size_t i = 0; i < model["sequences"].size(); ++i) {
    const auto& r = model["sequences"][i];
    EXPECT_EQ(r.contains("wind_share"), r.contains("wind_moved_mm")) << i;  // the sequences with wind
    if (!r.contains("wind_moved_mm")) continue;
    ++windy;
    const double mm_per_unit = 1000.0 / r["scale"].get<double>();
    // Frames first .. first + n - 1 from input frame first - 1: the twin is 0.01 t away, and within
    // the window 0.01 (t - input frame).
    const int first = r["first_frame"].get<int>(), n = static_cast<int>(r["error_curve_mm"].size());
    double apart = 0, in_window = 0;
    for (int t = first; t < first + n; ++t) {
      apart += 0.01 * t / n;
      in_window += 0.01 * (t - first + 1) / n;
    }
    EXPECT_NEAR(r["twin_moved_mm"].get<double>(), apart * mm_per_unit, 1e-4 * mm_per_unit);
    EXPECT_NEAR(r["twin_moved_in_window_mm"].get<double>(), in_window * mm_per_unit, 1e-4 * mm_per_unit);
    // The rise is what two evaluations, with the wind x 0 and with the data's, tell apart.
    const double rise = r["error_mm"].get<double>() - data_wind["methods"][0]["sequences"][i]["error_mm"].get<double>();
    EXPECT_NEAR(r["wind_error_rise_mm"].get<double>(), rise, 1e-6 * mm_per_unit);
    EXPECT_TRUE(std::isfinite(r["wind_share"].get<double>()));
  }
  EXPECT_GT(windy, 0);
  EXPECT_EQ(model["summary"]["wind_share"]["sequences"].get<int>(), windy);
  for (std::size_t k = 1; k < calm["methods"].size(); ++k)  // baselines see the data's wind: nothing to compare
    EXPECT_FALSE(calm["methods"][k]["summary"].contains("wind_share")) << calm["methods"][k]["name"];
  const std::string md = slurp(root_ / "eval_twins" / "eval.md");
  EXPECT_NE(md.find("share of Blender's movement"), std::string::npos) << md;
  EXPECT_NE(text.find("against Blender's twins ("), std::string::npos) << text;

  // Twins need a changed wind, the wind they were made with, and a folder that exists.
  const auto [no_scale, _1] = report(" --wind-twins " + twins.string(), "eval_twins_bad", &code);
  EXPECT_NE(code, 0);
  EXPECT_NE(no_scale.find("give --wind-scale"), std::string::npos) << no_scale;
  const auto [other_scale, _2] = report(" --wind-scale 2 --wind-twins " + twins.string(), "eval_twins_bad", &code);
  EXPECT_NE(code, 0);
  EXPECT_NE(other_scale.find((twins / "scene.json").string()), std::string::npos) << other_scale;
  EXPECT_NE(other_scale.find("pass --wind-scale 0"), std::string::npos) << other_scale;
  const auto [missing, _3] = report(" --wind-scale 0 --wind-twins " + (root_ / "no_twins").string(), "eval_twins_bad", &code);
  EXPECT_NE(code, 0);
  EXPECT_NE(missing.find("no such folder"), std::string::npos) << missing;
}

TEST_F(EvalCli, StartsAfterTheRampByDefaultOrAtAFixedInputFrame) {
  // A copy of the data whose first test sequence has the generator's ramp attributes (the
  // second has none and takes the fixed start, data.first_frame = 2).
  const fs::path data = root_ / "data_ramp";
  fs::copy(root_ / "data", data, fs::copy_options::recursive);
  const dataset::DatasetManifest manifest = dataset::read_manifest(data.string());
  const std::vector<std::string> ids = manifest.split("test");
  ASSERT_EQ(ids.size(), 2u);
  const hid_t f = H5Fopen(manifest.sequence_path(ids[0]).c_str(), H5F_ACC_RDWR, H5P_DEFAULT);
  ASSERT_GE(f, 0);
  dataset::h5::write_int_attr(f, "rest_frames", 2);
  dataset::h5::write_int_attr(f, "ramp_frames", 3);
  H5Fclose(f);
  const auto starts = [&](const std::string& flags) {
    int code = 0;
    const fs::path out = root_ / "eval_start";
    const std::string text = run("eval --dataset " + data.string() + " --frames 2 --speed-frames 1 " + flags +
                                     " --out " + out.string(),
                                 &code);
    EXPECT_EQ(code, 0) << text;
    const auto j = nlohmann::json::parse(slurp(out / "eval.json"));
    std::vector<std::pair<int, std::string>> first;  // (first predicted frame, start) per sequence
    for (const auto& m : j["methods"])  // the same start for every method
      for (size_t i = 0; i < m["sequences"].size(); ++i) {
        const auto& s = m["sequences"][i];
        if (first.size() <= i) first.push_back({s["first_frame"].get<int>(), s["start"].get<std::string>()});
        EXPECT_EQ(s["first_frame"].get<int>(), first[i].first) << m["name"];
        EXPECT_EQ(s["input_frame"].get<int>(), first[i].first - 1);
        EXPECT_EQ(s["error_curve_mm"].size(), 2u);
      }
    return first;
  };
  using Starts = std::vector<std::pair<int, std::string>>;
  EXPECT_EQ(starts(""), (Starts{{5, "ramp"}, {3, "fixed"}}));  // 2 + 3 = 5
  EXPECT_EQ(starts("--start ramp --start-frame 4"), (Starts{{5, "ramp"}, {5, "fixed"}}));
  EXPECT_EQ(starts("--start fixed"), (Starts{{3, "fixed"}, {3, "fixed"}}));
  EXPECT_EQ(starts("--start-frame 6"), (Starts{{7, "fixed"}, {7, "fixed"}}));
  int code = 0;
  const std::string bad = run("eval --dataset " + data.string() + " --start later", &code);
  EXPECT_NE(code, 0) << bad;
}

TEST(SelectSequences, IdsAndRangesInSplitOrderAndEntriesThatMatchNothingNamed) {
  const std::vector<std::string> split = {"00040", "00041", "00048", "00050", "00083", "00090"};
  using V = std::vector<std::string>;
  EXPECT_EQ(select_sequences(split, {}, "val", "d/dataset.json"), split);
  EXPECT_EQ(select_sequences(split, {"00048..00083"}, "val", "d/dataset.json"), (V{"00048", "00050", "00083"}));
  EXPECT_EQ(select_sequences(split, {"00090", "00040", "00040..00041"}, "val", "d/dataset.json"),
            (V{"00040", "00041", "00090"}));
  for (const std::string entry : {"00042", "00084..00089", "00083..00048"}) {
    try {
      select_sequences(split, {entry}, "val", "d/dataset.json");
      ADD_FAILURE() << entry << " was accepted";
    } catch (const std::runtime_error& e) {
      const std::string what = e.what();
      EXPECT_NE(what.find("d/dataset.json"), std::string::npos) << what;
      EXPECT_NE(what.find("'val'"), std::string::npos) << what;
      EXPECT_NE(what.find(entry), std::string::npos) << what;
    }
  }
}

TEST_F(EvalCli, SequencesOptionEvaluatesOnlyTheNamedOnes) {
  const std::vector<std::string> ids = dataset::read_manifest((root_ / "data").string()).split("test");
  ASSERT_EQ(ids.size(), 2u);
  int code = 0;
  const fs::path out = root_ / "eval_sequences";
  const std::string text = run("eval --dataset " + (root_ / "data").string() + " --frames 1 --sequences " + ids[1] +
                                   " --out " + out.string(),
                               &code);
  ASSERT_EQ(code, 0) << text;
  const auto report = nlohmann::json::parse(slurp(out / "eval.json"));
  EXPECT_EQ(report["sequences_selected"], nlohmann::json::array({ids[1]}));
  EXPECT_NE(slurp(out / "eval.md").find("sequences `" + ids[1] + "`"), std::string::npos);
  const auto methods = report["methods"];
  ASSERT_FALSE(methods.empty());
  for (const auto& m : methods) {
    ASSERT_EQ(m["sequences"].size(), 1u) << m["name"];
    EXPECT_EQ(m["sequences"][0]["id"].get<std::string>(), ids[1]);
  }
  const std::string bad = run("eval --dataset " + (root_ / "data").string() + " --sequences nothing_here --out " +
                                  (root_ / "x").string(),
                              &code);
  EXPECT_EQ(code, 1) << bad;
  EXPECT_NE(bad.find("nothing_here"), std::string::npos) << bad;
}

TEST_F(EvalCli, RunDirectoryPicksBestElseTheNewestCheckpoint) {
  const fs::path run_dir = root_ / "run";
  fs::create_directories(run_dir / "checkpoints");
  fs::copy_file(root_ / "tiny.h5", run_dir / "checkpoints" / "step_00000002.h5");
  fs::copy_file(root_ / "vanilla.h5", run_dir / "checkpoints" / "step_00000010.h5");
  int code = 0;
  const auto names = [&] {
    const std::string text = run("eval --run " + run_dir.string() + " --frames 1 --speed-frames 1 --max-sequences 1 --out " +
                                     (root_ / "eval_run").string(),
                                 &code);
    EXPECT_EQ(code, 0) << text;
    return nlohmann::json::parse(slurp(root_ / "eval_run" / "eval.json"))["methods"][0]["checkpoint"].get<std::string>();
  };
  EXPECT_NE(names().find("step_00000010.h5"), std::string::npos);
  fs::copy_file(root_ / "tiny.h5", run_dir / "best.h5");
  EXPECT_NE(names().find("best.h5"), std::string::npos);
  const std::string bad = run("eval --run " + (root_ / "data").string() + " --out " + (root_ / "x").string(), &code);
  EXPECT_NE(code, 0);
  EXPECT_NE(bad.find("no best.h5"), std::string::npos) << bad;
}

// pack, export and stress learn the model (and its config) from --run as eval does; giving both
// ways, or neither where a model is needed, is a usage error before any work.
TEST_F(EvalCli, EveryModelCommandTakesARunDirectory) {
  const fs::path run_dir = root_ / "run_any";
  fs::create_directories(run_dir / "checkpoints");
  fs::copy_file(root_ / "tiny.h5", run_dir / "checkpoints" / "step_00000004.h5");
  int code = 0;
  const fs::path packed = root_ / "packed.h5";
  std::string text = run("pack --run " + run_dir.string() + " --out " + packed.string(), &code);
  ASSERT_EQ(code, 0) << text;
  EXPECT_NE(text.find("step_00000004.h5"), std::string::npos) << text;
  EXPECT_TRUE(fs::exists(packed));
  text = run("export --run " + run_dir.string() + " --frames 1 --strip-frames 0 --out " + (root_ / "exp_run").string(),
             &code);
  ASSERT_EQ(code, 0) << text;
  EXPECT_TRUE(fs::exists(root_ / "exp_run" / "body_0003.obj")) << text;
  text = run("stress --run " + run_dir.string() + " --checkpoint " + (root_ / "tiny.h5").string(), &code);
  EXPECT_EQ(code, 2) << text;
  EXPECT_NE(text.find("excludes"), std::string::npos) << text;
  text = run("stress --frames 4", &code);
  EXPECT_EQ(code, 2) << text;
  EXPECT_NE(text.find("--checkpoint FILE or --run DIR"), std::string::npos) << text;
  text = run("pack --out " + (root_ / "none.h5").string(), &code);
  EXPECT_EQ(code, 2) << text;
  EXPECT_FALSE(fs::exists(root_ / "none.h5"));
}

TEST_F(EvalCli, ExportWritesMeshesAndAStrip) {
  int code = 0;
  const fs::path out = root_ / "export";
  const std::string text = run("export --checkpoint " + (root_ / "tiny.h5").string() +
                                   " --frames 2 --strip-frames 2 --out " + out.string(),
                               &code);
  ASSERT_EQ(code, 0) << text;
  // 2 frames x (body + 2 garments x pred/gt) = 10 OBJ files.
  int objs = 0;
  for (const auto& e : fs::directory_iterator(out)) objs += e.path().extension() == ".obj";
  EXPECT_EQ(objs, 10) << text;
  const std::string obj = slurp(out / "body_0003.obj");
  EXPECT_EQ(obj.rfind("v ", 0), 0u);
  EXPECT_NE(obj.find("\nf "), std::string::npos);
  const std::string png = slurp(out / "strip.png");
  ASSERT_GT(png.size(), 8u);
  EXPECT_EQ(png.substr(1, 3), "PNG");
  // PLY through the baseline path.
  const std::string t2 = run("export --dataset " + (root_ / "data").string() +
                                 " --baseline constant-velocity --frames 1 --strip-frames 0 --format ply --out " +
                                 (root_ / "ply").string(),
                             &code);
  ASSERT_EQ(code, 0) << t2;
  EXPECT_EQ(slurp(root_ / "ply" / "body_0003.ply").rfind("ply\nformat binary_little_endian", 0), 0u);
}

// Arguments that cannot mean anything are refused before any file is read or model run: the
// message names the option and the value (the checkpoint need not exist).
TEST(EvalCliArguments, NonFiniteNegativeOrEmptySettingsAreRefusedFirst) {
  const std::pair<const char*, const char*> cases[] = {
      {"stress --checkpoint none.h5 --winds 0,nan", "--winds: 'nan' is not a finite number >= 0"},
      {"stress --checkpoint none.h5 --winds inf", "--winds: 'inf' is not a finite number >= 0"},
      {"stress --checkpoint none.h5 --tether -1", "--tether: '-1' is not a finite number >= 0"},
      {"stress --checkpoint none.h5 --speed nan", "--speed: 'nan' is not a finite number >= 0"},
      {"stress --checkpoint none.h5 --frames 2", "--frames: Value 2 not in range 4 to 1000000"},
      {"eval --checkpoint none.h5 --speed-frames 0", "--speed-frames: Value 0 not in range 1 to 1000000"},
      {"eval --checkpoint none.h5 --tether 3,-2", "--tether: '-2' is not a finite number >= 0"},
      {"eval --checkpoint none.h5 --constraints maybe", "--constraints"},
  };
  for (const auto& [args, message] : cases) {
    int code = 0;
    const std::string text = cli_test::run_cli(args, &code);
    EXPECT_NE(code, 0) << args;
    EXPECT_NE(text.find(message), std::string::npos) << args << "\n" << text;
    EXPECT_EQ(text.find("none.h5"), std::string::npos) << args << ": read before the arguments were checked\n" << text;
  }
}

TEST(Render, DrawsATriangleOverTheBackground) {
  Image im(32, 32);
  dataset::Points x(3, 3);
  x << 0, 0, 0, 1, 0, 0, 0, 0, 1;  // in the x-z plane: faces the +y view
  dataset::Faces f(1, 3);
  f << 0, 1, 2;
  View v;
  v.fit({{&x, &f, {255, 0, 0}}});
  render(im, v, {{&x, &f, {255, 0, 0}}});
  int red = 0;
  for (size_t i = 0; i < im.depth.size(); ++i) red += im.rgb[3 * i] == 255 && im.rgb[3 * i + 1] == 0;
  EXPECT_GT(red, 32 * 32 / 4);  // about half of the fitted square
  EXPECT_LT(red, 32 * 32 * 3 / 4);
}

}  // namespace
}  // namespace layersnet::eval

namespace layersnet::eval {
namespace {

// Not a test: writes a freshly initialised checkpoint for a config, for measuring speed
// before a trained model exists. Run with
//   LAYERSNET_FRESH_CONFIG=configs/default.toml LAYERSNET_FRESH_OUT=/tmp/fresh.h5
//   build/tests/test_eval --gtest_also_run_disabled_tests --gtest_filter='*WriteFreshCheckpoint'
TEST(Tool, DISABLED_WriteFreshCheckpoint) {
  const char* config = std::getenv("LAYERSNET_FRESH_CONFIG");
  const char* out = std::getenv("LAYERSNET_FRESH_OUT");
  ASSERT_TRUE(config && out) << "set LAYERSNET_FRESH_CONFIG and LAYERSNET_FRESH_OUT";
  const Config c = load_config({config});
  ad::ParamStore<float> ps;
  model::register_params(ps, c.model);
  model::init_params(ps, c.model, 1);
  Checkpoint cp;
  cp.config_toml = to_toml(c);
  write_checkpoint(out, ps, cp);
}

}  // namespace
}  // namespace layersnet::eval
