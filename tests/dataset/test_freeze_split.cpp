// scripts/freeze_train_split.py: training on the part of a data set that exists while the rest
// is still being generated.
#include "dataset/manifest.h"
#include "dataset/stats.h"
#include "dataset/synthetic.h"
#include "test_util.h"

#include <cstdlib>
#include <filesystem>
#include <fstream>

namespace layersnet::dataset {
namespace {

namespace fs = std::filesystem;
const std::string kScript = std::string(LAYERSNET_SOURCE_DIR) + "/scripts/freeze_train_split.py";

int freeze(const fs::path& data, const fs::path& out, const std::string& options = "") {
  return std::system(
      ("/usr/bin/python3 " + kScript + " " + data.string() + " " + out.string() + " " + options + " > /dev/null 2>&1").c_str());
}

// Two of four training files are still missing: the frozen set lists the two that exist, keeps
// validation and test whole, carries the generator's extra keys, and its statistics are those of
// the original set's statistics over just those two training sequences.
TEST(FreezeTrainSplit, KeepsTheTrainingSequencesThatExistAndTheWholeOtherSplits) {
  const auto tmp = testing::temp_dir("freeze");
  const fs::path dir = tmp;
  DatasetManifest growing = write_synthetic_dataset((dir / "growing").string(), 4, 1, 2);
  growing.extra["tags"] = {{"s0000", {{"wind", "calm"}}}};
  write_manifest(growing);
  fs::remove(growing.sequence_path("s0001"));
  fs::remove(growing.sequence_path("s0003"));
  ASSERT_EQ(freeze(dir / "growing", dir / "frozen"), 0);

  const DatasetManifest frozen = read_manifest((dir / "frozen").string());
  EXPECT_EQ(frozen.train, (std::vector<std::string>{"s0000", "s0002"}));
  EXPECT_EQ(frozen.val, growing.val);
  EXPECT_EQ(frozen.test, growing.test);
  EXPECT_EQ(frozen.extra.at("tags"), growing.extra.at("tags"));
  EXPECT_EQ(frozen.extra.at("frozen_from").at("train_sequences_listed"), 4);

  DatasetManifest two = growing;  // statistics read the training split only
  two.train = {"s0000", "s0002"};
  const NormalisationStats a = compute_stats(frozen), b = compute_stats(two);
  EXPECT_EQ(a.sequences, b.sequences);
  for (const auto& q : kStatQuantities) {
    EXPECT_EQ((a.*q.field).mean, (b.*q.field).mean) << q.name;
    EXPECT_EQ((a.*q.field).std, (b.*q.field).std) << q.name;
  }

  // --max-train keeps the first N that exist, and refuses more than exist.
  ASSERT_EQ(freeze(dir / "growing", dir / "first", "--max-train 1"), 0);
  EXPECT_EQ(read_manifest((dir / "first").string()).train, (std::vector<std::string>{"s0000"}));
  EXPECT_NE(freeze(dir / "growing", dir / "three", "--max-train 3"), 0);

  // A test split still being made (one of its two files missing) is emptied: training never reads it.
  fs::remove(growing.sequence_path(growing.test.front()));
  ASSERT_EQ(freeze(dir / "growing", dir / "no_test"), 0);
  EXPECT_TRUE(read_manifest((dir / "no_test").string()).test.empty());
  EXPECT_EQ(read_manifest((dir / "no_test").string()).val, growing.val);

  // --add links another set's training sequences under its folder's name, with their tags; its
  // validation and test stay out, and asking for more than exist is refused.
  DatasetManifest extra = write_synthetic_dataset((dir / "extra").string(), 3, 1, 1);
  extra.extra["tags"] = {{"s0001", {{"wind", "windy"}}}, {"s0003", {{"wind", "calm"}}}};
  write_manifest(extra);
  ASSERT_EQ(freeze(dir / "growing", dir / "both", "--max-train 1 --add " + (dir / "extra").string() + ":2"), 0);
  const DatasetManifest both = read_manifest((dir / "both").string());
  EXPECT_EQ(both.train, (std::vector<std::string>{"s0000", "extra_" + extra.train[0], "extra_" + extra.train[1]}));
  EXPECT_EQ(both.val, growing.val);
  EXPECT_EQ(both.extra.at("tags").at("extra_s0001").at("wind"), "windy");
  EXPECT_FALSE(both.extra.at("tags").contains("extra_s0003"));
  EXPECT_EQ(both.extra.at("frozen_from").at("added").at(0).at("train_sequences"), 2);
  EXPECT_TRUE(fs::exists(both.sequence_path("extra_" + extra.train[1])));
  EXPECT_NE(freeze(dir / "growing", dir / "too_many", "--add " + (dir / "extra").string() + ":4"), 0);

  // A folder that already holds a manifest is not overwritten; an incomplete validation split is refused.
  EXPECT_NE(freeze(dir / "growing", dir / "frozen"), 0);
  fs::remove(growing.sequence_path(growing.val.front()));
  EXPECT_NE(freeze(dir / "growing", dir / "frozen_again"), 0);
  EXPECT_FALSE(fs::exists(dir / "frozen_again" / "dataset.json"));
}

}  // namespace
}  // namespace layersnet::dataset
