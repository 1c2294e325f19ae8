// The generation driver (dataset/generate.h) without Blender: splits, gates, seeds, and a whole
// run against a stand-in "blender" that copies a synthetic sequence and writes a report as
// make_sequence.py does
// (retries, the manifest through write_manifest with tags and subsets, resume).
#include "dataset/generate.h"
#include "dataset/manifest.h"
#include "dataset/synthetic.h"
#include "test_util.h"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <filesystem>
#include <fstream>

namespace layersnet::dataset {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

json passing_report() {
  return {{"finite", true},
          {"quality",
           {{"inside_body_share", 0.0}, {"outer_inside_inner_share", 0.0}, {"max_edge_stretch", 1.5}, {"p99_edge_stretch", 0.2}}}};
}

TEST(GenerateDriver, SplitsAreContiguousBlocksWithOneValAndTestFromThree) {
  EXPECT_EQ(split_names(2, 0.125, 0.125), (std::vector<std::string>{"train", "train"}));
  EXPECT_EQ(split_names(3, 0.125, 0.125), (std::vector<std::string>{"train", "val", "test"}));
  const auto s = split_names(16, 0.125, 0.125);
  EXPECT_EQ(std::count(s.begin(), s.end(), "train"), 12);
  EXPECT_EQ(s[11], "train");
  EXPECT_EQ(s[12], "val");
  EXPECT_EQ(s[14], "test");
}

TEST(GenerateDriver, ListedRangesKeepValAndTestIndicesAndRefuseBadLists) {
  const auto s = split_names_from_ranges(10, json::parse(R"({"val": [[3, 4]], "test": [[4, 6]]})"), "r.json");
  EXPECT_EQ(s, (std::vector<std::string>{"train", "train", "train", "val", "test", "test", "train", "train", "train",
                                         "train"}));
  auto message = [](const char* ranges) {
    try {
      split_names_from_ranges(10, json::parse(ranges), "r.json: /split_ranges");
    } catch (const GenerateError& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  EXPECT_NE(message(R"({"val": [[3, 5]], "test": [[4, 6]]})").find("index 4 is listed twice"), std::string::npos);
  EXPECT_NE(message(R"({"test": [[8, 11]]})").find("r.json: /split_ranges/test: [8,11] must satisfy"), std::string::npos);
  EXPECT_NE(message(R"({"train": [[0, 2]]})").find("unknown split 'train'"), std::string::npos);
  EXPECT_NE(message(R"({"val": [3, 4]})").find("is not a [first, end) pair"), std::string::npos);
}

TEST(GenerateDriver, GatesNameWhatFailed) {
  EXPECT_TRUE(failed_gates(passing_report(), Gates{}).empty());
  json r = passing_report();
  r["finite"] = false;
  r["quality"]["p99_edge_stretch"] = 3.0;
  const auto failed = failed_gates(r, Gates{});
  ASSERT_EQ(failed.size(), 2u);
  EXPECT_EQ(failed[0], "non-finite positions");
  EXPECT_EQ(failed[1].rfind("p99_edge_stretch 3 > 1", 0), 0u) << failed[1];
  EXPECT_NE(sequence_seed(1, 0, 0), sequence_seed(1, 0, 1));
  EXPECT_NE(sequence_seed(1, 0, 0), sequence_seed(1, 1, 0));
  EXPECT_EQ(sequence_seed(7, 3, 2), sequence_seed(7, 3, 2));
}

TEST(GenerateDriver, WholeRunWithAStandInBlender) {
  const fs::path dir = testing::temp_path("generate");
  const DatasetManifest synthetic = write_synthetic_dataset((dir / "synthetic").string(), 1, 0, 0);
  // The stand-in fails its first attempt of sequence 00001 (a gate), then passes.
  const fs::path blender = dir / "fake_blender.sh";
  {
    std::ofstream f(blender);
    f << "#!/bin/sh\n"
         "[ \"$1\" = --version ] && exit 0\n"
         "while [ $# -gt 0 ]; do case \"$1\" in --out) out=$2;; --report) rep=$2;; --split) split=$2;; esac; shift; done\n"
         "cp '" << synthetic.sequence_path("s0000") << "' \"$out\"\n"
         "share=0.0\n"
         "case \"$out\" in *00001.h5) [ -e \"$out.retried\" ] || { share=0.5; touch \"$out.retried\"; };; esac\n"
         "cat > \"$rep\" <<EOF\n"
         "{\"split\": \"$split\", \"finite\": true, \"quality\": {\"inside_body_share\": $share, \"outer_inside_inner_share\": 0.0,\n"
         " \"max_edge_stretch\": 1.5, \"p99_edge_stretch\": 0.2}, \"tags\": {\"inner\": \"tight\", \"wind\": \"windy\"},\n"
         " \"timing\": {\"blender_s_per_frame\": 0.5, \"blender_cpu_s_per_frame\": 0.25, \"total_s\": 2.0},\n"
         " \"frames\": 6, \"body_vertices\": 10, \"cloth_vertices\": 20}\n"
         "EOF\n";
  }
  fs::permissions(blender, fs::perms::owner_all);
  const fs::path recipe = dir / "recipe.json";
  std::ofstream(recipe) << R"({"count": 3, "seed": 4, "scene": {"frames": 6}})";
  GenerateOptions o;
  o.out = (dir / "out").string();
  o.recipe = recipe.string();
  o.script = "make_sequence.py";  // only passed on to the stand-in
  o.blender = blender.string();
  const GenerateSummary first = generate_dataset(o);
  EXPECT_EQ(first.accepted, 3);
  EXPECT_EQ(first.dropped, 0);
  EXPECT_EQ(first.regenerated, 1);

  const DatasetManifest m = read_manifest(o.out);
  EXPECT_EQ(m.train, std::vector<std::string>{"00000"});
  EXPECT_EQ(m.val, std::vector<std::string>{"00001"});
  EXPECT_EQ(m.test, std::vector<std::string>{"00002"});
  EXPECT_NE(m.source.find("seed 4, count 3"), std::string::npos) << m.source;
  EXPECT_EQ(m.extra["subsets"]["T+W"].size(), 3u);
  EXPECT_EQ(m.extra["tags"]["00002"]["inner"], "tight");
  EXPECT_TRUE(m.extra.contains("subset_rule"));
  std::ifstream in(fs::path(o.out) / "generate_report.json");
  const json report = json::parse(in);
  EXPECT_EQ(report["sequences"][1]["status"], "regenerated");
  EXPECT_EQ(report["sequences"][1]["attempts"], 2);
  // The set's cost: the three accepted jobs' 2 s of wall time and 0.25 s of CPU per frame.
  EXPECT_DOUBLE_EQ(report["summary"]["kept_blender_job_seconds"].get<double>(), 6.0);
  EXPECT_DOUBLE_EQ(report["summary"]["kept_blender_cpu_seconds"].get<double>(), 4.5);
  EXPECT_TRUE(fs::exists(fs::path(o.out) / "generate_report.md"));

  // Resume: every sequence is kept, the manifest is written again the same.
  const auto written = fs::last_write_time(fs::path(o.out) / "00002.h5");
  const GenerateSummary again = generate_dataset(o);
  EXPECT_EQ(again.accepted, 3);
  EXPECT_EQ(again.regenerated, 0);
  EXPECT_EQ(fs::last_write_time(fs::path(o.out) / "00002.h5"), written);
  std::ifstream in2(fs::path(o.out) / "generate_report.json");
  const json report2 = json::parse(in2);
  for (const json& e : report2["sequences"]) EXPECT_EQ(e["status"], "kept");
  EXPECT_DOUBLE_EQ(report2["summary"]["kept_blender_job_seconds"].get<double>(), 6.0);  // what resuming kept
  const DatasetManifest m2 = read_manifest(o.out);
  EXPECT_EQ(m2.all_ids(), m.all_ids());
  EXPECT_EQ(m2.extra, m.extra);

  // Growing the training split: listed ranges keep val and test at their indices, so the three
  // sequences are kept and only the new index is simulated, as train.
  std::ofstream(recipe) << R"({"count": 4, "seed": 4, "split_ranges": {"val": [[1, 2]], "test": [[2, 3]]},
                               "scene": {"frames": 6}})";
  const GenerateSummary grown = generate_dataset(o);
  EXPECT_EQ(grown.accepted, 4);
  EXPECT_EQ(fs::last_write_time(fs::path(o.out) / "00002.h5"), written);
  const DatasetManifest m3 = read_manifest(o.out);
  EXPECT_EQ(m3.train, (std::vector<std::string>{"00000", "00003"}));
  EXPECT_EQ(m3.val, m.val);
  EXPECT_EQ(m3.test, m.test);

  // A train limit makes only the training split's first N (by index); without it the rest follows.
  std::ofstream(recipe) << R"({"count": 6, "seed": 4, "split_ranges": {"val": [[1, 2]], "test": [[2, 3]]},
                               "scene": {"frames": 6}})";
  o.train_limit = 3;
  EXPECT_EQ(generate_dataset(o).accepted, 5);
  EXPECT_EQ(read_manifest(o.out).train, (std::vector<std::string>{"00000", "00003", "00004"}));
  EXPECT_FALSE(fs::exists(fs::path(o.out) / "00005.h5"));
  o.train_limit = -1;
  EXPECT_EQ(generate_dataset(o).accepted, 6);
  EXPECT_EQ(read_manifest(o.out).train, (std::vector<std::string>{"00000", "00003", "00004", "00005"}));
  std::ofstream(recipe) << R"({"count": 4, "seed": 4, "test_fraction": 0.25, "split_ranges": {"test": [[3, 4]]}})";
  EXPECT_THROW(generate_dataset(o), GenerateError);
  fs::remove_all(dir);
}

}  // namespace
}  // namespace layersnet::dataset
