// `layersnet bench dataset_memory DIR`: peak resident memory of one training epoch over a
// data set much larger than the loader's caches (goal: a 2 GB data set must
// iterate in under 1 GB). `--make-gb 2` first writes a synthetic data set of that size.
#include "cli/command_registry.h"
#include "dataset/loader.h"
#include "dataset/stats.h"
#include "dataset/synthetic.h"

#include <chrono>
#include <cstdio>
#include <filesystem>

namespace {
using namespace layersnet::dataset;
namespace fs = std::filesystem;

struct MemoryOptions {
  std::string root;
  double make_gb = 0;
  int stride = 4;
  int64_t cache_mb = 256;
  int chunk_frames = 32;
};

int64_t folder_bytes(const std::string& root) {
  int64_t b = 0;
  for (const auto& e : fs::directory_iterator(root))
    if (e.is_regular_file() && e.path().extension() == ".h5") b += static_cast<int64_t>(e.file_size());
  return b;
}

double mib(int64_t b) { return static_cast<double>(b) / (1 << 20); }

int make(const MemoryOptions& o) {
  SyntheticOptions so;
  so.frames = 300;
  so.garments = 2;
  so.rings = 100;
  so.segments = 64;
  so.body_rings = 100;
  so.body_segments = 64;
  so.height = 0.147f * 99 / 0.8f;
  so.uv_per_unit = 0.1f;
  so.wind = true;
  if (o.make_gb < 0.1) {  // a small data set for examples and quick checks
    so.frames = 40;
    so.rings = so.body_rings = 20;
    so.height = 0.147f * 19 / 0.8f;
  }
  const Sequence probe = make_synthetic_sequence(so);
  const double per_sequence = static_cast<double>(probe.info.bytes_per_frame()) * so.frames;
  const int n = std::max(3, static_cast<int>(o.make_gb * (1 << 30) / per_sequence + 0.999));
  std::printf("writing %d sequences of %.1f MiB (%d frames, %ld vertices per frame) to %s ...\n", n,
              per_sequence / (1 << 20), so.frames,
              static_cast<long>(probe.info.num_body_vertices + probe.info.total_garment_vertices()), o.root.c_str());
  write_synthetic_dataset(o.root, n - 2, 1, 1, so);
  std::printf("done: %.1f MiB of sequence files\n", mib(folder_bytes(o.root)));
  return 0;
}

int run_memory(const MemoryOptions& o) {
  if (o.make_gb > 0) return make(o);
  const auto t0 = std::chrono::steady_clock::now();
  const DatasetManifest m = read_manifest(o.root);
  if (!fs::exists(m.stats_path())) write_stats(m.stats_path(), compute_stats(m));
  const NormalisationStats stats = load_stats_or_explain(m);
  const int64_t rss_after_stats = peak_rss_bytes();
  LoaderOptions lo;
  lo.frame_stride = o.stride;
  lo.cache_bytes = o.cache_mb << 20;
  lo.chunk_frames = o.chunk_frames;
  SampleLoader loader(m, "train", stats, lo);
  int64_t samples = 0, vertices = 0;
  while (auto s = loader.next()) {
    ++samples;
    vertices += s->num_vertices();
  }
  const double sec = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  const auto& c = loader.counters();
  std::printf("data set %s: %.1f MiB of sequence files, %zu training sequences\n", o.root.c_str(),
              mib(folder_bytes(o.root)), m.train.size());
  std::printf("epoch: %ld samples (every %d-th frame), %.1f s; read %.1f MiB of positions in %ld chunks "
              "(%ld cache hits), files opened %ld\n",
              static_cast<long>(samples), o.stride, sec, mib(c.bytes_read), static_cast<long>(c.chunks_read),
              static_cast<long>(c.chunk_hits), static_cast<long>(c.files_opened));
  std::printf("cache budget %ld MiB, peak cached %.1f MiB; peak RSS after stats %.1f MiB, after the epoch %.1f MiB\n",
              static_cast<long>(o.cache_mb), mib(c.peak_cached_bytes), mib(rss_after_stats), mib(peak_rss_bytes()));
  (void)vertices;
  return 0;
}

}  // namespace

LAYERSNET_BENCH(dataset_memory, "Peak memory of one lazy training epoch (use --make-gb 2 to create data)",
                [](CLI::App& sub) {
                  auto opts = std::make_shared<MemoryOptions>();
                  sub.add_option("dataset", opts->root, "data-set folder")->required();
                  sub.add_option("--make-gb", opts->make_gb, "write a synthetic data set of about this many GiB and exit");
                  sub.add_option("--stride", opts->stride, "use every k-th sample frame (all frames are still read)");
                  sub.add_option("--cache-mb", opts->cache_mb, "loader cache budget in MiB");
                  sub.add_option("--chunk-frames", opts->chunk_frames, "sample frames per lazily read chunk");
                  return [opts] { return run_memory(*opts); };
                });
