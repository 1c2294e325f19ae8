// Lazy sample loader with bounded caches (see loader.h).
#include "dataset/loader.h"

#include <sys/resource.h>

#include <algorithm>
#include <fstream>

namespace layersnet::dataset {

SampleLoader::SampleLoader(DatasetManifest manifest, const std::string& split, NormalisationStats stats,
                           LoaderOptions options)
    : manifest_(std::move(manifest)),
      stats_(std::move(stats)),
      options_(options),
      ids_(manifest_.split(split)),
      structures_(options.sample.patch_size, 64) {
  options_.chunk_frames = std::max(options_.chunk_frames, 1);
  options_.chunks_in_flight = std::max(options_.chunks_in_flight, 1);
  options_.frame_stride = std::max(options_.frame_stride, 1);
  for (const auto& id : ids_) {
    // Frame count only: the header is read again (lazily) when the sequence is used.
    const SequenceFile f(manifest_.sequence_path(id));
    std::vector<int> all = sample_frames(f.info().num_frames, options_.frames), kept;
    for (size_t i = 0; i < all.size(); i += static_cast<size_t>(options_.frame_stride)) kept.push_back(all[i]);
    num_samples_ += static_cast<int64_t>(kept.size());
    frames_.push_back(std::move(kept));
  }
  start_epoch(0);
}

std::vector<int> SampleLoader::chunk_frames(int sequence, int c) const {
  const auto& f = frames_[sequence];
  const size_t b = static_cast<size_t>(c) * options_.chunk_frames;
  return {f.begin() + static_cast<std::ptrdiff_t>(std::min(b, f.size())),
          f.begin() + static_cast<std::ptrdiff_t>(std::min(b + options_.chunk_frames, f.size()))};
}

void SampleLoader::start_epoch(uint64_t epoch) {
  rng_.seed(options_.seed * 0x9E3779B97F4A7C15ull + epoch);
  order_.clear();
  for (int s = 0; s < static_cast<int>(ids_.size()); ++s) {
    const int n = static_cast<int>((frames_[s].size() + options_.chunk_frames - 1) / options_.chunk_frames);
    for (int c = 0; c < n; ++c) order_.push_back({s, c});
  }
  if (options_.shuffle) std::shuffle(order_.begin(), order_.end(), rng_);
  next_chunk_ = 0;
  buffer_.clear();
  next_in_buffer_ = 0;
}

SampleLoader::OpenFile& SampleLoader::open(int sequence) {
  for (auto it = files_.begin(); it != files_.end(); ++it)
    if (it->first == sequence) {
      files_.splice(files_.begin(), files_, it);
      return files_.front().second;
    }
  auto file = std::make_shared<SequenceFile>(manifest_.sequence_path(ids_[sequence]));
  ++counters_.files_opened;
  auto info = std::make_shared<const SequenceInfo>(file->info());
  files_.emplace_front(sequence, OpenFile{std::move(file), std::move(info)});
  while (static_cast<int>(files_.size()) > std::max(options_.max_open_files, 1)) files_.pop_back();
  return files_.front().second;
}

std::shared_ptr<const SampleLoader::Chunk> SampleLoader::chunk(const ChunkKey& key) {
  for (auto it = chunks_.begin(); it != chunks_.end(); ++it)
    if (it->first == key) {
      chunks_.splice(chunks_.begin(), chunks_, it);
      ++counters_.chunk_hits;
      return chunks_.front().second;
    }
  const std::vector<int> ts = chunk_frames(key.sequence, key.chunk);
  OpenFile& f = open(key.sequence);
  auto c = std::make_shared<Chunk>();
  c->info = f.info;
  const int first = ts.front() - 2, last = ts.back() + 1;
  c->window = f.file->read_frames(first, last - first + 1);
  const int64_t bytes = c->window.bytes();
  ++counters_.chunks_read;
  counters_.bytes_read += bytes;
  chunks_.emplace_front(key, c);
  counters_.cached_bytes += bytes;
  // Evict least recently used chunks beyond the budget (the newest always stays).
  while (chunks_.size() > 1 && counters_.cached_bytes > options_.cache_bytes) {
    counters_.cached_bytes -= chunks_.back().second->window.bytes();
    chunks_.pop_back();
  }
  counters_.peak_cached_bytes = std::max(counters_.peak_cached_bytes, counters_.cached_bytes);
  return c;
}

TrainingSample SampleLoader::sample(int sequence, int t) {
  const auto& f = frames_.at(sequence);
  const auto pos = std::find(f.begin(), f.end(), t);
  if (pos == f.end())
    throw DatasetError(manifest_.sequence_path(ids_.at(sequence)), "/",
                       "frame " + std::to_string(t) + " is not a sample frame of this loader");
  const int c = static_cast<int>((pos - f.begin()) / options_.chunk_frames);
  const auto ch = chunk({sequence, c});
  TrainingSample s = build_sample(*ch->info, ch->window, t, stats_, structures_.get(ids_[sequence], *ch->info),
                                  options_.sample);
  s.sequence_id = ids_[sequence];
  return s;
}

std::optional<TrainingSample> SampleLoader::next() {
  if (next_in_buffer_ >= buffer_.size()) {
    buffer_.clear();
    next_in_buffer_ = 0;
    for (int k = 0; k < options_.chunks_in_flight && next_chunk_ < order_.size(); ++k, ++next_chunk_) {
      const ChunkKey key = order_[next_chunk_];
      for (int t : chunk_frames(key.sequence, key.chunk)) buffer_.emplace_back(key, t);
    }
    if (buffer_.empty()) return std::nullopt;
    if (options_.shuffle) std::shuffle(buffer_.begin(), buffer_.end(), rng_);
  }
  const auto [key, t] = buffer_[next_in_buffer_++];
  const auto ch = chunk(key);
  TrainingSample s = build_sample(*ch->info, ch->window, t, stats_, structures_.get(ids_[key.sequence], *ch->info),
                                  options_.sample);
  s.sequence_id = ids_[key.sequence];
  return s;
}

int64_t current_rss_bytes() {
  std::ifstream in("/proc/self/statm");
  int64_t pages = 0, resident = 0;
  in >> pages >> resident;
  return resident * 4096;
}

int64_t peak_rss_bytes() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return static_cast<int64_t>(u.ru_maxrss) * 1024;
}

}  // namespace layersnet::dataset
