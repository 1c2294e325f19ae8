// TrainData, the one lazy loader: every sample frame once, samples built from a window equal
// those built from the fully read sequence, reads bounded to the window, open files bounded,
// cached sequences read as fresh ones.
#include "train/train_data.h"

#include "dataset/error.h"
#include "dataset/synthetic.h"
#include "model/sample_input.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <set>

namespace layersnet {
namespace {

namespace fs = std::filesystem;

class TrainDataTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("layersnet_train_data_" + std::to_string(::getpid()));
    fs::remove_all(dir_);
    dataset::SyntheticOptions o;
    o.frames = 12;
    o.garments = 2;
    o.wind = true;
    dataset::SequenceWriteOptions w;
    w.gzip = 1;
    manifest_ = dataset::write_synthetic_dataset(dir_.string(), 3, 1, 0, o, w);
    stats_ = dataset::compute_stats(manifest_);
    config_.data.first_frame = 2;
    config_.data.max_frames = 0;
  }
  void TearDown() override {
    std::error_code ec;
    fs::remove_all(dir_, ec);
  }
  fs::path dir_;
  dataset::DatasetManifest manifest_;
  dataset::NormalisationStats stats_;
  Config config_;
};

TEST_F(TrainDataTest, EverySampleFrameOnceAndSamplesMatchTheFullSequence) {
  TrainData data(manifest_, "train", stats_, config_);
  ASSERT_EQ(data.num_samples(), 3 * 9);  // t = 2..10 of 12 frames
  std::set<std::pair<int, int>> seen;
  for (const SampleRef& r : data.samples()) EXPECT_TRUE(seen.insert({r.sequence, r.t}).second);
  const SampleRef r = data.samples()[13];
  const dataset::TrainingSample s = data.build(data.read_window(r.sequence, r.t, r.t), r.t);
  const dataset::Sequence full = dataset::read_sequence(manifest_.sequence_path(data.ids()[r.sequence]));
  const dataset::TrainingSample e =
      dataset::build_sample(full.info, full.frames, r.t, stats_, nullptr, model::sample_options_for(config_.model));
  EXPECT_EQ(s.sequence_id, data.ids()[r.sequence]);
  EXPECT_EQ(e.frame, s.frame);
  EXPECT_EQ(e.state, s.state);
  EXPECT_EQ(e.body_state_norm, s.body_state_norm);
  EXPECT_EQ(e.target, s.target);
  EXPECT_EQ(e.world_edges.items, s.world_edges.items);
  EXPECT_EQ(e.body_neighbours.index, s.body_neighbours.index);
}

TEST_F(TrainDataTest, ReadsOnlyTheWindowAndKeepsOpenFilesWithinTheBound) {
  config_.data.cache_sequences = 1;
  TrainData data(manifest_, "train", stats_, config_);
  const dataset::SequenceFile f(manifest_.sequence_path("s0000"));
  // Frames t-2 .. t+1 of one sample; t-2 .. t+3 of a 3-step window.
  (void)data.read_window(0, 4, 4);
  EXPECT_EQ(data.reads().bytes, 4 * f.info().bytes_per_frame());
  (void)data.read_window(0, 4, 6);
  EXPECT_EQ(data.reads().bytes, 10 * f.info().bytes_per_frame());
  EXPECT_EQ(data.reads().windows, 2);
  EXPECT_EQ(data.reads().files_opened, 1);
  // One open file: alternating sequences reopens each time.
  (void)data.read_window(1, 4, 4);
  (void)data.read_window(0, 4, 4);
  EXPECT_EQ(data.reads().files_opened, 3);
  config_.data.cache_sequences = 2;
  TrainData two(manifest_, "train", stats_, config_);
  for (int s : {0, 1, 0, 1}) (void)two.read_window(s, 4, 4);
  EXPECT_EQ(two.reads().files_opened, 2);
}

// With every sequence of the split cached (as configs/large.toml keeps them), each file is opened
// once however the reads alternate, and a cached sequence gives the window and sample a fresh
// reader gives: caching changes the cost, never the data.
TEST_F(TrainDataTest, CachingEverySequenceOpensEachOnceAndReadsWhatAFreshReaderReads) {
  config_.model.velocity_base = "physics";  // the sample's physics step too, as the recipe builds it
  config_.data.cache_sequences = 3;         // the whole training split
  TrainData cached(manifest_, "train", stats_, config_);
  config_.data.cache_sequences = 1;
  for (int pass = 0; pass < 2; ++pass)
    for (int s : {0, 1, 2, 1, 0, 2}) {
      TrainData fresh(manifest_, "train", stats_, config_);
      const Window a = cached.read_window(s, 4 + s, 6 + s), b = fresh.read_window(s, 4 + s, 6 + s);
      EXPECT_EQ(a.sequence_id, b.sequence_id);
      EXPECT_EQ(a.frames.first, b.frames.first);
      EXPECT_EQ(a.frames.body, b.frames.body);
      EXPECT_EQ(a.frames.garments, b.frames.garments);
      const dataset::TrainingSample x = cached.build(a, 5 + s), y = fresh.build(b, 5 + s);
      EXPECT_EQ(x.state, y.state);
      EXPECT_EQ(x.target, y.target);
      EXPECT_EQ(x.world_edges.items, y.world_edges.items);
      EXPECT_EQ(x.body_neighbours.index, y.body_neighbours.index);
      EXPECT_EQ(x.physics_step, y.physics_step);
      EXPECT_GT(x.physics_step.rows(), 0);
    }
  EXPECT_EQ(cached.reads().files_opened, 3);
  EXPECT_EQ(cached.reads().windows, 12);
}

// data.mirror adds each training file's mirror image as a sequence of its own (index n + i),
// with the same sample frames: its window is the file's window with x → −x, its sample is built
// from the mirrored faces, and one open file serves both. Validation is left as it is.
TEST_F(TrainDataTest, MirrorAddsEachTrainingFilesImage) {
  config_.model.velocity_base = "physics";
  config_.data.cache_sequences = 3;
  TrainData plain(manifest_, "train", stats_, config_);
  config_.data.mirror = true;
  TrainData both(manifest_, "train", stats_, config_);
  ASSERT_EQ(both.ids().size(), 6u);
  EXPECT_EQ(both.ids()[4], plain.ids()[1] + " mirrored");
  EXPECT_EQ(both.num_samples(), 2 * plain.num_samples());
  EXPECT_EQ(both.reads().files_opened, 6);  // every sequence cached: the images beside the files
  const Eigen::Matrix3f M = Eigen::Vector3f(-1.f, 1.f, 1.f).asDiagonal();
  const Window a = plain.read_window(1, 5, 6), b = both.read_window(4, 5, 6), same = both.read_window(1, 5, 6);
  EXPECT_EQ(same.frames.body, a.frames.body);
  EXPECT_EQ(b.frames.body, a.frames.body * M);
  EXPECT_EQ(b.frames.garments[1], a.frames.garments[1] * M);
  EXPECT_EQ(b.info->garments[1].faces.col(1), a.info->garments[1].faces.col(2));
  const dataset::TrainingSample x = plain.build(a, 5), y = both.build(b, 5);
  EXPECT_EQ(y.sequence_id, both.ids()[4]);
  EXPECT_EQ(y.target.leftCols(3), x.target.leftCols(3) * M);
  EXPECT_EQ(y.world_edges.items, x.world_edges.items);
  const float size = x.physics_step.cwiseAbs().maxCoeff();
  ASSERT_GT(size, 0.f);
  EXPECT_LT((y.physics_step - x.physics_step * M).cwiseAbs().maxCoeff(), 1e-5f * size);
  EXPECT_EQ(both.reads().files_opened, 6);
  EXPECT_EQ(TrainData(manifest_, "val", stats_, config_).ids().size(), 1u);
}

TEST_F(TrainDataTest, FrameSelectionFollowsTheConfig) {
  config_.data.max_frames = 4;  // t = 2, 3, 4
  EXPECT_EQ(TrainData(manifest_, "train", stats_, config_).num_samples(), 3 * 3);
  config_.data.first_frame = 60;  // past the end of 12-frame sequences: no samples
  config_.data.max_frames = 0;
  EXPECT_EQ(TrainData(manifest_, "train", stats_, config_).num_samples(), 0);
  config_.data.first_frame = 2;
  TrainData val(manifest_, "val", stats_, config_);
  EXPECT_EQ(val.build(val.read_window(0, 4, 4), 4).frame, 4);
  EXPECT_THROW(val.read_window(0, 11, 11), dataset::DatasetError);  // frame 12 does not exist
}

}  // namespace
}  // namespace layersnet
