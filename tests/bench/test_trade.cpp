// `layersnet bench trade`: the Pareto front and preset choice on hand-made points, and the
// whole sweep end to end (2 variants, 1 tiny epoch each) on a tiny synthetic data set.
#include "dataset/stats.h"
#include "dataset/synthetic.h"
#include "bench/pareto.h"

#include "tests/eval/cli_test_util.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>

namespace layersnet::eval {
namespace {

namespace fs = std::filesystem;
using Points = std::vector<TradePoint>;

TEST(Pareto, DominatedPointsAreExcludedAndTheFrontIsSortedBySpeed) {
  // c is dominated by b (slower and worse); e by a (same speed, worse error).
  const Points p = {{"a", 10, 100}, {"b", 20, 80}, {"c", 30, 90}, {"d", 40, 50}, {"e", 10, 120}};
  EXPECT_EQ(pareto_front(p), (std::vector<std::size_t>{0, 1, 3}));
}

TEST(Pareto, IdenticalPointsBothStayEqualCoordinateAloneDominates) {
  // a and b tie exactly: neither dominates. c ties a's error but is slower: dominated.
  const Points p = {{"a", 10, 100}, {"b", 10, 100}, {"c", 15, 100}, {"d", 5, 200}};
  EXPECT_EQ(pareto_front(p), (std::vector<std::size_t>{3, 0, 1}));
}

TEST(Pareto, InvalidPointsAreNeverOnTheFrontAndNeverDominate) {
  const Points p = {{"nan error", 1, NAN}, {"no speed", -1, 1}, {"inf", INFINITY, 1}, {"ok", 50, 60}};
  EXPECT_EQ(pareto_front(p), (std::vector<std::size_t>{3}));
  EXPECT_TRUE(pareto_front({}).empty());
  EXPECT_FALSE(trade_point_valid({"zero ms", 0, 1}));
}

TEST(Pareto, PresetsFollowTheirDefinitions) {
  // Reference (default) = index 2: 40 ms, 100 mm. Tolerance 10 %: error ≤ 110.
  const Points p = {{"tiny", 5, 200},     {"small", 12, 108}, {"default", 40, 100},
                    {"big", 160, 90},     {"slow bad", 170, 300}};
  const PresetChoice c = choose_presets(p, 2, 0.10);
  EXPECT_EQ(c.fast, 1);      // fastest within 110 mm (tiny is faster but 200 mm)
  EXPECT_EQ(c.accurate, 3);  // lowest error
  // Between fast (small) and accurate (big) only "default", above the log-log chord: no
  // knee, so the lowest error × ms of small 1296, default 4000, big 14400 -> small.
  EXPECT_EQ(c.balanced, 1);
  // A tighter tolerance excludes "small" (108 > 105): the default itself is the fast preset.
  EXPECT_EQ(choose_presets(p, 2, 0.05).fast, 2);
  // No valid reference: fast = the fastest front point.
  EXPECT_EQ(choose_presets(p, -1, 0.10).fast, 0);
  // A knee: b lies 0.027 (log units) below the chord a–c, although a has the lowest error × ms.
  const Points k = {{"a", 10, 200}, {"b", 50, 120}, {"c", 100, 100}};
  const PresetChoice ck = choose_presets(k, 0, 0.10);
  EXPECT_EQ(ck.fast, 0);
  EXPECT_EQ(ck.accurate, 2);
  EXPECT_EQ(ck.balanced, 1);
  const PresetChoice none = choose_presets({{"x", NAN, NAN}}, 0, 0.1);
  EXPECT_EQ(none.fast, -1);
  EXPECT_EQ(none.balanced, -1);
  EXPECT_EQ(none.accurate, -1);
}

std::string run(const std::string& args, int* code) { return cli_test::run_cli(args, code); }
using cli_test::slurp;

TEST(BenchTrade, TwoVariantsEndToEndThenReused) {
  const fs::path root = fs::temp_directory_path() / ("layersnet_trade_test_" + std::to_string(::getpid()));
  fs::remove_all(root);
  dataset::SyntheticOptions so;
  so.garments = 2;
  so.frames = 8;
  so.rings = 4;
  so.segments = 8;
  so.body_rings = 4;
  so.body_segments = 8;
  const auto m = dataset::write_synthetic_dataset((root / "data").string(), 2, 1, 1, so);
  dataset::write_stats(m.stats_path(), dataset::compute_stats(m));
  const fs::path out = root / "trade";
  const std::string args = "bench trade --config " + std::string(LAYERSNET_SOURCE_DIR) + "/configs/tiny.toml --set data.dataset=" +
                           (root / "data").string() + " --set train.threads=1 --budget-epochs 1 --variants default,layers_2 " +
                           "--frames 3 --speed-frames 2 --eval-threads 1 --out " + out.string();
  int code = 0;
  const std::string text = run(args, &code);
  ASSERT_EQ(code, 0) << text;
  EXPECT_NE(text.find("[1/2] default"), std::string::npos) << text;
  EXPECT_NE(text.find("ETA"), std::string::npos) << text;
  const auto j = nlohmann::json::parse(slurp(out / "trade.json"));
  ASSERT_EQ(j["variants"].size(), 2u);
  EXPECT_EQ(j["settings"]["budget_epochs"], 1);
  for (const auto& v : j["variants"]) {
    SCOPED_TRACE(v["name"].get<std::string>());
    EXPECT_EQ(v["status"], "ok");
    const auto& r = v["result"];
    for (const char* k : {"error_mm", "ms_per_frame_1thread", "ms_per_frame_2threads", "h_collision_percent"}) {
      ASSERT_TRUE(r[k].is_number()) << k;
      EXPECT_TRUE(std::isfinite(r[k].get<double>())) << k;
    }
    EXPECT_GT(r["error_mm"].get<double>(), 0.0);
    EXPECT_GT(v["train"]["samples_per_s"].get<double>(), 0.0);
    EXPECT_GT(v["train"]["peak_mb"].get<double>(), 1.0);
    EXPECT_GT(v["eval"]["peak_mb"].get<double>(), 1.0);
    EXPECT_GT(v["params"].get<double>(), 0.0);
  }
  EXPECT_EQ(j["variants"][1]["sets"][0], "model.layers=2");
  // tiny.toml has 1 layer: the 2-layer variant has more parameters.
  EXPECT_GT(j["variants"][1]["params"].get<double>(), j["variants"][0]["params"].get<double>());
  // Speed re-measured back to back after the sweep (3 passes): the table uses the fastest.
  ASSERT_TRUE(j.contains("speed"));
  for (const auto& v : j["variants"]) {
    const auto& passes = v["result"]["ms_per_frame_1thread_passes"];
    ASSERT_EQ(passes.size(), 3u);
    double best = 1e300;
    for (const auto& x : passes) best = std::min(best, x.get<double>());
    EXPECT_EQ(v["result"]["ms_per_frame_1thread"].get<double>(), best);
  }
  EXPECT_TRUE(fs::exists(out / "speed" / "pass3" / "eval.json"));
  ASSERT_GE(j["front"].size(), 1u);
  for (const char* p : {"fast", "balanced", "accurate"}) {
    ASSERT_TRUE(j["presets"].contains(p)) << p;
    const std::string preset = slurp(out / "presets" / (std::string(p) + ".toml"));
    EXPECT_NE(preset.find("include = \"tiny.toml\""), std::string::npos) << preset;
  }
  const std::string md = slurp(out / "trade.md");
  EXPECT_NE(md.find("| default |"), std::string::npos) << md;
  EXPECT_NE(md.find("| layers_2 |"), std::string::npos) << md;
  EXPECT_NE(md.find("**balanced**"), std::string::npos) << md;
  if (std::system("command -v gnuplot >/dev/null 2>&1") == 0) {
    EXPECT_TRUE(fs::exists(out / "trade.png"));
  }

  // Rerun: both variants are reused, nothing is trained again.
  const std::string again = run(args, &code);
  ASSERT_EQ(code, 0) << again;
  EXPECT_NE(again.find("reused"), std::string::npos) << again;
  EXPECT_EQ(again.find("train: layersnet"), std::string::npos) << again;
  EXPECT_NE(again.find("speed: reused"), std::string::npos) << again;

  // A larger budget continues both trainings (train --resume to 2 epochs) and evaluates again.
  std::string args2 = args;
  args2.replace(args2.find("--budget-epochs 1"), 17, "--budget-epochs 2");
  const std::string more = run(args2, &code);
  ASSERT_EQ(code, 0) << more;
  EXPECT_NE(more.find("train --resume"), std::string::npos) << more;
  const auto j2 = nlohmann::json::parse(slurp(out / "trade.json"));
  EXPECT_EQ(j2["settings"]["budget_epochs"], 2);
  for (const auto& v : j2["variants"]) {
    EXPECT_EQ(v["budget_epochs"], 2);
    EXPECT_TRUE(v["train_resumed"].get<bool>());
    EXPECT_GE(v["train"]["wall_s"].get<double>(), v["train_before"]["wall_s"].get<double>());
  }
  // The run's log says the second epoch ran.
  EXPECT_NE(slurp(out / "variants" / "default" / "train.log").find("epoch 2"), std::string::npos);
  if (!std::getenv("LAYERSNET_TRADE_TEST_KEEP")) fs::remove_all(root);
}

}  // namespace
}  // namespace layersnet::eval
