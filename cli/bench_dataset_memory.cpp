// `layersnet bench dataset_memory DIR`: peak resident memory of one training epoch read the way
// the trainer reads it (TrainData: a frame window per sample, a bounded LRU of open sequences
// and their structures) over a data set much larger than that bound (goal: a 2 GB data set must
// iterate in under 1 GB). `--make-gb 2` first writes a synthetic data set of that size.
#include "cli/command_registry.h"
#include "cli/program_files.h"
#include "dataset/stats.h"
#include "dataset/synthetic.h"
#include "run/config.h"
#include "train/gsl_random.h"
#include "train/train_data.h"

#include <sys/resource.h>

#include <chrono>
#include <cstdio>
#include <filesystem>

namespace {
using namespace layersnet::dataset;
namespace fs = std::filesystem;

struct MemoryOptions {
  std::string root;
  double make_gb = 0;
  bool dlayers_size = false;  // --make-gb writes scenes of D-LAYERS size instead
  int stride = 4;
  std::string config;  // patch size, radii, frame selection; the defaults without it
  int cache_sequences = 0;  // 0: the config's data.cache_sequences
};

int64_t folder_bytes(const std::string& root) {
  int64_t b = 0;
  for (const auto& e : fs::directory_iterator(root))
    if (e.is_regular_file() && e.path().extension() == ".h5") b += static_cast<int64_t>(e.file_size());
  return b;
}

double mib(int64_t b) { return static_cast<double>(b) / (1 << 20); }

int64_t peak_rss_bytes() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return static_cast<int64_t>(u.ru_maxrss) * 1024;  // Linux: kilobytes
}

int make(const MemoryOptions& o) {
  SyntheticOptions so;
  so.frames = 300;
  so.garments = 2;
  so.rings = 100;
  so.segments = 64;
  so.body_rings = 100;
  so.body_segments = 64;
  so.uv_per_unit = 0.1f;
  so.wind = true;
  if (o.make_gb < 0.1) {  // a small data set for examples and quick checks
    so.frames = 40;
    so.rings = so.body_rings = 20;
  }
  if (o.dlayers_size) {  // 2 x 10,000 garment vertices and a 6,890-vertex body (SMPL), as D-LAYERS
    so.frames = 40;
    so.rings = 125;
    so.segments = 80;
    so.body_rings = 106;
    so.body_segments = 65;
  }
  so.height = 0.147f * static_cast<float>(so.rings - 1) / 0.8f;  // rows 0.147 units apart (the tube spans 0.8 of its height)
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
  layersnet::Config config =
      o.config.empty() ? layersnet::Config{} : layersnet::load_config({layersnet::cli::resolve_user_file(o.config)});
  if (o.cache_sequences > 0) config.data.cache_sequences = o.cache_sequences;
  layersnet::TrainData data(m, "train", stats, config);
  // Every stride-th sample frame of each sequence, in a shuffled order as the trainer's epoch.
  std::vector<layersnet::SampleRef> order;
  for (std::size_t i = 0; i < data.samples().size(); ++i) {
    const layersnet::SampleRef r = data.samples()[i];
    if ((r.t - data.first_t(r.sequence)) % std::max(o.stride, 1) == 0) order.push_back(r);
  }
  layersnet::GslRandom(0).shuffle(order);
  for (const layersnet::SampleRef& r : order) (void)data.build(data.read_window(r.sequence, r.t, r.t), r.t);
  const double sec = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  const auto& c = data.reads();
  std::printf("data set %s: %.1f MiB of sequence files, %zu training sequences\n", o.root.c_str(),
              mib(folder_bytes(o.root)), m.train.size());
  std::printf("epoch: %zu samples (every %d-th frame), %.1f s; read %.1f MiB of positions in %ld windows, "
              "files opened %ld\n",
              order.size(), o.stride, sec, mib(c.bytes), static_cast<long>(c.windows),
              static_cast<long>(c.files_opened));
  std::printf("open sequences at most %d; peak RSS after stats %.1f MiB, after the epoch %.1f MiB\n",
              config.data.cache_sequences, mib(rss_after_stats), mib(peak_rss_bytes()));
  return 0;
}

}  // namespace

LAYERSNET_BENCH(dataset_memory, "Peak memory of one lazy training epoch (use --make-gb 2 to create data)",
                [](CLI::App& sub) {
                  auto opts = std::make_shared<MemoryOptions>();
                  sub.add_option("dataset", opts->root, "data-set folder")->required();
                  sub.add_option("--make-gb", opts->make_gb, "write a synthetic data set of about this many GiB and exit");
                  sub.add_flag("--dlayers-size", opts->dlayers_size,
                               "with --make-gb: scenes of D-LAYERS size (20,000 garment and 6,890 body vertices, 40 frames)");
                  sub.add_option("--stride", opts->stride, "use every k-th sample frame (at 4 every frame is read once)");
                  sub.add_option("-c,--config", opts->config, "config file: patch size, radii, frames used (default: the defaults)");
                  sub.add_option("--cache-sequences", opts->cache_sequences,
                                 "sequences kept open with their structures (data.cache_sequences)");
                  return [opts] { return run_memory(*opts); };
                });
