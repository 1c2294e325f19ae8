// The generation driver with several Blender processes at once (`--jobs`), against a stand-in
// "blender" that copies a synthetic sequence and writes a report as make_sequence.py does:
// every sequence gets the seed of its index whatever the job count, a run interrupted mid-way
// leaves a dataset.json of what is finished, and resuming simulates only what is missing.
#include "dataset/generate.h"
#include "dataset/manifest.h"
#include "dataset/synthetic.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <filesystem>
#include <fstream>
#include <set>
#include <string>

namespace layersnet::dataset {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

json read(const fs::path& p) {
  std::ifstream in(p);
  return json::parse(in);
}

// Stand-in Blender: sleeps a little (so jobs overlap), records each seed it was given and,
// for sequence `snapshot_id`, copies the dataset.json that exists while it runs.
fs::path write_stand_in(const fs::path& dir, const std::string& synthetic_file, const std::string& snapshot_id) {
  const fs::path blender = dir / "fake_blender.sh";
  std::ofstream f(blender);
  f << "#!/bin/sh\n"
       "[ \"$1\" = --version ] && exit 0\n"
       "while [ $# -gt 0 ]; do case \"$1\" in --out) out=$2;; --report) rep=$2;; --split) split=$2;; --seed) seed=$2;; esac; shift; done\n"
       "sleep 0.2\n"
       "echo \"$out $seed\" >> '" << (dir / "seeds.txt").string() << "'\n"
       "case \"$out\" in *" << snapshot_id << ".h5) cp \"$(dirname \"$out\")/dataset.json\" '" << (dir / "snapshot.json").string()
    << "' 2>/dev/null;; esac\n"
       "cp '" << synthetic_file << "' \"$out\"\n"
       "cat > \"$rep\" <<EOF\n"
       "{\"split\": \"$split\", \"finite\": true, \"quality\": {\"inside_body_share\": 0.0, \"outer_inside_inner_share\": 0.0,\n"
       " \"max_edge_stretch\": 1.5, \"p99_edge_stretch\": 0.2},\n"
       " \"tags\": {\"inner\": \"loose\", \"wind\": \"calm\", \"outfit\": \"unseen\", \"motion\": \"procedural\"},\n"
       " \"timing\": {\"blender_s_per_frame\": 0.5}, \"body_vertices\": 10, \"cloth_vertices\": 20}\n"
       "EOF\n";
  f.close();
  fs::permissions(blender, fs::perms::owner_all);
  return blender;
}

TEST(GenerateJobs, SeedsPerIndexPeriodicManifestAndResume) {
  const fs::path dir = fs::temp_directory_path() / "layersnet_test_generate_jobs";
  fs::remove_all(dir);
  fs::create_directories(dir);
  const DatasetManifest synthetic = write_synthetic_dataset((dir / "synthetic").string(), 1, 0, 0);
  const fs::path blender = write_stand_in(dir, synthetic.sequence_path("s0000"), "00007");
  const fs::path recipe = dir / "recipe.json";
  std::ofstream(recipe) << R"({"count": 8, "seed": 9, "split_ranges": {"val": [[5, 6]], "test": [[6, 8]]},
                               "scene": {"frames": 6}})";
  GenerateOptions o;
  o.out = (dir / "out").string();
  o.recipe = recipe.string();
  o.script = "make_sequence.py";  // only passed on to the stand-in
  o.blender = blender.string();
  o.jobs = 3;
  o.manifest_every = 1;
  const GenerateSummary first = generate_dataset(o);
  EXPECT_EQ(first.accepted, 8);

  // The seed of a sequence depends on its index only, not on which job ran it.
  std::ifstream seeds(dir / "seeds.txt");
  std::string path;
  long long seed = 0;
  int lines = 0;
  while (seeds >> path >> seed) {
    const int index = std::stoi(fs::path(path).stem().string());
    EXPECT_EQ(seed, sequence_seed(9, index, 0)) << path;
    ++lines;
  }
  EXPECT_EQ(lines, 8);

  // While a later sequence ran, dataset.json already listed finished ones (an interrupted run
  // leaves a usable manifest).
  ASSERT_TRUE(fs::exists(dir / "snapshot.json"));
  const DatasetManifest snapshot = parse_manifest(read(dir / "snapshot.json").dump(), "snapshot");
  EXPECT_GE(snapshot.all_ids().size(), 1u);
  EXPECT_LT(snapshot.all_ids().size(), 8u);

  const DatasetManifest m = read_manifest(o.out);
  EXPECT_EQ(m.train, (std::vector<std::string>{"00000", "00001", "00002", "00003", "00004"}));
  EXPECT_EQ(m.test, (std::vector<std::string>{"00006", "00007"}));
  // Named test subsets from the outfit and motion tags.
  EXPECT_EQ(m.extra["subsets"]["test_unseen_outfit"].size(), 2u);
  EXPECT_EQ(m.extra["subsets"]["test_calm"].size(), 2u);
  EXPECT_EQ(m.extra["subsets"]["test_procedural_motion"].size(), 2u);
  EXPECT_FALSE(m.extra["subsets"].contains("test_seen_outfit"));
  EXPECT_EQ(read(fs::path(o.out) / "generate_report.json")["summary"]["jobs"], 3);
  const std::string solved_source = read(fs::path(o.out) / "dataset.json")["source"];
  EXPECT_EQ(solved_source.rfind("layersnet generate: Blender cloth", 0), 0u) << solved_source;
  // Each report names the Blender thread count (a re-simulation must use the same).
  EXPECT_EQ(read(fs::path(o.out) / "reports" / "00004.json")["blender_threads"], o.threads);

  // A sequence killed mid-way (its file written, its accepted report not yet) is simulated
  // again; the others are kept.
  fs::remove(fs::path(o.out) / "reports" / "00003.json");
  fs::remove(dir / "seeds.txt");
  o.jobs = 2;
  const GenerateSummary again = generate_dataset(o);
  EXPECT_EQ(again.accepted, 8);
  const json report = read(fs::path(o.out) / "generate_report.json");
  std::set<std::string> simulated;
  for (const json& e : report["sequences"])
    if (e["status"] != "kept") simulated.insert(e["id"].get<std::string>());
  EXPECT_EQ(simulated, std::set<std::string>{"00003"});
  // A recipe without the solver says so where every reader of the data set looks.
  const fs::path carried_recipe = dir / "carried.json";
  std::ofstream(carried_recipe) << R"({"count": 1, "seed": 9, "split_ranges": {}, "scene": {"frames": 6, "cloth": "surface"}})";
  GenerateOptions carried = o;
  carried.recipe = carried_recipe.string(), carried.out = (dir / "carried").string();
  EXPECT_EQ(generate_dataset(carried).accepted, 1);
  const std::string carried_source = read(dir / "carried" / "dataset.json")["source"];
  EXPECT_NE(carried_source.find("no cloth solver (not simulated cloth)"), std::string::npos) << carried_source;
  EXPECT_THROW(
      [&] {
        GenerateOptions bad = o;
        bad.jobs = 0;
        generate_dataset(bad);
      }(),
      GenerateError);
  fs::remove_all(dir);
}

}  // namespace
}  // namespace layersnet::dataset
