#pragma once
// Lazy, memory-bounded iteration over the training samples of a data-set split (a data
// set larger than RAM must still train).
//
// Nothing per-frame is read up front: construction opens each sequence once to learn its
// frame count, then closes it. An epoch is a list of "chunks" — up to chunk_frames sample
// frames of one sequence, whose positions (frames t-2 .. t+1 of those samples) are read with
// one hyperslab per array when first needed. Chunks are shuffled, then taken
// chunks_in_flight at a time and their samples shuffled together (a shuffle buffer), so
// the working set is about chunks_in_flight chunks. Loaded chunks live in an LRU cache
// bounded by cache_bytes; open files and sequence headers in an LRU of max_open_files; the
// static structure (patches) in a bounded StructureCache. Memory is therefore bounded by
// the options, not by the data-set size.
#include "dataset/manifest.h"
#include "dataset/sample.h"
#include "dataset/sequence.h"
#include "dataset/stats.h"

#include <cstdint>
#include <list>
#include <map>
#include <memory>
#include <optional>
#include <random>
#include <string>
#include <vector>

namespace layersnet::dataset {

struct LoaderOptions {
  int64_t cache_bytes = int64_t{256} << 20;  // loaded frame windows kept (LRU)
  int chunk_frames = 32;      // sample frames per chunk
  int chunks_in_flight = 4;   // shuffle-buffer width in chunks
  int max_open_files = 8;     // open sequence files / headers kept (LRU)
  bool shuffle = true;
  uint64_t seed = 0;
  int frame_stride = 1;       // use every k-th sample frame (1 = all)
  FrameSelection frames;      // which t give samples (FrameSelection::official() = 63..98)
  SampleOptions sample;
};

struct LoaderCounters {
  int64_t chunks_read = 0;       // cache misses
  int64_t chunk_hits = 0;
  int64_t bytes_read = 0;        // positions read from disk (in memory, float32)
  int64_t cached_bytes = 0;      // now
  int64_t peak_cached_bytes = 0;
  int64_t files_opened = 0;
};

class SampleLoader {
 public:
  SampleLoader(DatasetManifest manifest, const std::string& split, NormalisationStats stats,
               LoaderOptions options = {});
  int64_t num_samples() const { return num_samples_; }
  // Orders the next epoch's samples (a different shuffle per epoch; same seed + epoch =
  // same order).
  void start_epoch(uint64_t epoch);
  // The next sample of the epoch, or nullopt at its end.
  std::optional<TrainingSample> next();
  // One specific sample (sequence index in the split, frame t).
  TrainingSample sample(int sequence, int t);
  const LoaderCounters& counters() const { return counters_; }
  const std::vector<std::string>& sequence_ids() const { return ids_; }

 private:
  struct ChunkKey {
    int sequence, chunk;
    auto operator<=>(const ChunkKey&) const = default;
  };
  struct Chunk {
    std::shared_ptr<const SequenceInfo> info;
    FrameWindow window;
  };
  struct OpenFile {
    std::shared_ptr<SequenceFile> file;
    std::shared_ptr<const SequenceInfo> info;
  };
  OpenFile& open(int sequence);
  std::shared_ptr<const Chunk> chunk(const ChunkKey& key);
  std::vector<int> chunk_frames(int sequence, int chunk) const;

  DatasetManifest manifest_;
  NormalisationStats stats_;
  LoaderOptions options_;
  std::vector<std::string> ids_;
  std::vector<std::vector<int>> frames_;  // sample frames t per sequence
  int64_t num_samples_ = 0;
  StructureCache structures_;
  std::list<std::pair<int, OpenFile>> files_;  // LRU, front = most recent
  std::list<std::pair<ChunkKey, std::shared_ptr<const Chunk>>> chunks_;  // LRU
  std::vector<ChunkKey> order_;     // chunks of the epoch
  size_t next_chunk_ = 0;
  std::vector<std::pair<ChunkKey, int>> buffer_;  // (chunk, t) of the current shuffle buffer
  size_t next_in_buffer_ = 0;
  std::mt19937_64 rng_;
  LoaderCounters counters_;
};

// Resident-set size of this process now and at its peak (bytes; Linux /proc).
int64_t current_rss_bytes();
int64_t peak_rss_bytes();

}  // namespace layersnet::dataset
