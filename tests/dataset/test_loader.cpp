// Lazy loader: every sample once per epoch, deterministic shuffles, bounded cache, and
// samples identical to those built from fully loaded sequences.
#include "dataset/loader.h"
#include "dataset/synthetic.h"
#include "test_util.h"

#include <set>

namespace layersnet::dataset {
namespace {

class Loader : public ::testing::Test {
 protected:
  void TearDown() override {
    std::error_code ec;
    std::filesystem::remove_all(dir_, ec);
  }
  void SetUp() override {
    dir_ = testing::temp_path("loader");
    SyntheticOptions o;
    o.frames = 12;
    o.garments = 2;
    o.wind = true;
    SequenceWriteOptions w;
    w.gzip = 1;
    manifest_ = write_synthetic_dataset(dir_.string(), 3, 1, 0, o, w);
    stats_ = compute_stats(manifest_);
  }
  std::filesystem::path dir_;
  DatasetManifest manifest_;
  NormalisationStats stats_;
};

TEST_F(Loader, EpochVisitsEverySampleOnceAndMatchesEagerSamples) {
  LoaderOptions o;
  o.chunk_frames = 3;
  o.chunks_in_flight = 2;
  o.seed = 5;
  SampleLoader loader(manifest_, "train", stats_, o);
  ASSERT_EQ(loader.num_samples(), 3 * 9);  // t = 2..10 of 12 frames
  std::set<std::pair<std::string, int>> seen;
  std::vector<std::pair<std::string, int>> order;
  while (auto s = loader.next()) {
    EXPECT_TRUE(seen.insert({s->sequence_id, s->frame}).second);
    order.emplace_back(s->sequence_id, s->frame);
    if (order.size() == 5) {  // compare one sample with the eager path
      const Sequence full = read_sequence(manifest_.sequence_path(s->sequence_id));
      const TrainingSample e = build_sample(full.info, full.frames, s->frame, stats_, nullptr);
      EXPECT_EQ(e.state, s->state);
      EXPECT_EQ(e.body_state_norm, s->body_state_norm);
      EXPECT_EQ(e.target, s->target);
      EXPECT_EQ(e.world_edges.items, s->world_edges.items);
      EXPECT_EQ(e.body_neighbours.index, s->body_neighbours.index);
    }
  }
  EXPECT_EQ(static_cast<int64_t>(seen.size()), loader.num_samples());
  // Shuffled (not in file order), reproducible per (seed, epoch), different across epochs.
  EXPECT_FALSE(std::is_sorted(order.begin(), order.end()));
  loader.start_epoch(0);
  std::vector<std::pair<std::string, int>> again;
  while (auto s = loader.next()) again.emplace_back(s->sequence_id, s->frame);
  EXPECT_EQ(again, order);
  loader.start_epoch(1);
  std::vector<std::pair<std::string, int>> other;
  while (auto s = loader.next()) other.emplace_back(s->sequence_id, s->frame);
  EXPECT_NE(other, order);
}

TEST_F(Loader, CacheStaysWithinItsBudget) {
  LoaderOptions o;
  o.chunk_frames = 2;
  o.chunks_in_flight = 1;
  o.shuffle = false;
  o.max_open_files = 1;
  SampleLoader probe(manifest_, "train", stats_, o);
  (void)probe.next();
  const int64_t one_chunk = probe.counters().cached_bytes;
  ASSERT_GT(one_chunk, 0);
  o.cache_bytes = 2 * one_chunk;
  SampleLoader loader(manifest_, "train", stats_, o);
  int n = 0;
  while (loader.next()) ++n;
  EXPECT_EQ(n, 27);
  EXPECT_LE(loader.counters().peak_cached_bytes, 2 * one_chunk);
  // Without shuffling each chunk is read exactly once: 5 chunks of 2 frames per sequence.
  EXPECT_EQ(loader.counters().chunks_read, 3 * 5);
  // Each chunk reads its sample frames plus 3 frames of context: 4 chunks of 5 frames and
  // one of 4 (t = 10) per sequence.
  const SequenceFile f(manifest_.sequence_path("s0000"));
  EXPECT_EQ(loader.counters().bytes_read, 3 * 24 * f.info().bytes_per_frame());
}

TEST_F(Loader, StrideAndOfficialSelection) {
  LoaderOptions o;
  o.frame_stride = 4;
  SampleLoader strided(manifest_, "train", stats_, o);
  EXPECT_EQ(strided.num_samples(), 3 * 3);  // t = 2, 6, 10
  o.frame_stride = 1;
  o.frames = FrameSelection::official();  // 12-frame sequences are too short: no samples
  SampleLoader official(manifest_, "train", stats_, o);
  EXPECT_EQ(official.num_samples(), 0);
  EXPECT_FALSE(official.next().has_value());
  SampleLoader val(manifest_, "val", stats_, LoaderOptions{});
  EXPECT_EQ(val.sample(0, 4).frame, 4);
  EXPECT_THROW(val.sample(0, 11), DatasetError);
}

}  // namespace
}  // namespace layersnet::dataset
