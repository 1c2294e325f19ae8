// `layersnet bench train`: training throughput (samples/s) of a config's model on a small
// synthetic scene (2 tube garments around a cylinder body, written to a temporary data set) or
// on a real data set (--dataset: reading and reopening files cost what they cost in `train`),
// at each requested thread count, and the share of a step spent outside the model
// (reading, sample building incl. neighbour search, gradient sum + optimizer). Each measurement
// is a `train` run (same code) stopped after --steps updates, without validation.
#include "cli/command_registry.h"
#include "autodiff/arena.h"
#include "dataset/stats.h"
#include "dataset/synthetic.h"
#include "train/trainer.h"

#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <memory>
#include <sstream>

namespace {

struct BenchTrainOptions {
  std::vector<std::string> files;
  std::vector<std::string> overrides;
  std::string dataset;  // empty: the synthetic scene
  std::vector<int> threads{1, 2};
  int steps = 8;
  int rings = 24;
  int segments = 64;
  int rollout = 0;
};

int run_bench_train(const BenchTrainOptions& o) {
  layersnet::ad::keep_freed_memory_in_process();  // as train
  namespace fs = std::filesystem;
  const fs::path dir = fs::temp_directory_path() / ("layersnet_bench_train_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  std::vector<std::string> data_sets;  // what the data set is: the synthetic scene or the config's own frames
  if (o.dataset.empty()) {
    layersnet::dataset::SyntheticOptions so;
    so.frames = 12;
    so.garments = 2;
    so.rings = o.rings;
    so.segments = o.segments;
    so.body_rings = o.rings;
    so.body_segments = o.segments;
    so.uv_per_unit = 0.1f;
    so.wind = true;
    const auto manifest = layersnet::dataset::write_synthetic_dataset((dir / "data").string(), 2, 0, 0, so);
    layersnet::dataset::write_stats(manifest.stats_path(), layersnet::dataset::compute_stats(manifest));
    data_sets = {"data.dataset=" + (dir / "data").string(), "data.first_frame=2", "data.max_frames=0"};
    std::printf("bench train: %s, scene of 2 garments x %d vertices + body %d vertices; %d updates per run, "
                "self-fed steps U{0..%d}\n",
                o.files.empty() ? "code defaults (official sizes)" : o.files.back().c_str(), o.rings * o.segments,
                o.rings * o.segments, o.steps, o.rollout);
  } else {
    data_sets = {"data.dataset=" + o.dataset};
    std::printf("bench train: %s on %s; %d updates per run, self-fed steps U{0..%d}\n",
                o.files.empty() ? "code defaults (official sizes)" : o.files.back().c_str(), o.dataset.c_str(), o.steps,
                o.rollout);
  }
  std::printf("%8s %12s %10s %10s %10s %10s %14s\n", "threads", "samples/s", "read_s", "build_s", "model_s",
              "optim_s", "outside_model");
  for (int t : o.threads) {
    std::vector<std::string> sets = o.overrides;
    std::ostringstream rollout;
    rollout << "train.rollout_steps=[" << o.rollout << "]";
    sets.insert(sets.end(), data_sets.begin(), data_sets.end());
    for (const std::string& s : {"train.max_steps=" + std::to_string(o.steps), std::string("train.validate=false"),
                                 std::string("train.validate_initial=false"),
                                 std::string("train.checkpoint_every=0"), "train.threads=" + std::to_string(t),
                                 rollout.str(), std::string("train.log_every=1000")})
      sets.push_back(s);
    const layersnet::Config config = layersnet::load_config(o.files, sets);
    layersnet::TrainOptions options;
    options.run_dir = (dir / ("run" + std::to_string(t))).string();
    std::ostringstream quiet;
    options.log = &quiet;
    const auto s = layersnet::train(config, options);
    const double outside = s.read_seconds + s.build_seconds + s.optimizer_seconds;
    std::printf("%8d %12.3f %10.2f %10.2f %10.2f %10.2f %13.1f%%\n", t, s.samples_per_second, s.read_seconds,
                s.build_seconds, s.model_seconds, s.optimizer_seconds, 100 * outside / (outside + s.model_seconds));
  }
  std::printf("build and model are thread-seconds; at 1 thread every column is wall time of the step.\n");
  fs::remove_all(dir);
  return 0;
}

}  // namespace

LAYERSNET_BENCH(train, "Training samples/s of a config on a small synthetic scene or a data set, per thread count", [](CLI::App& sub) {
  auto o = std::make_shared<BenchTrainOptions>();
  sub.add_option("--config,-c", o->files, "config file(s) (default: code defaults = official sizes)");
  sub.add_option("--set", o->overrides, "override one key");
  sub.add_option("--threads", o->threads, "thread counts to measure")->delimiter(',');
  sub.add_option("--steps", o->steps, "updates per measurement");
  sub.add_option("--rings", o->rings, "vertex rows of each garment and of the body");
  sub.add_option("--segments", o->segments, "vertices around each garment and the body");
  sub.add_option("--rollout", o->rollout, "max self-fed steps T_n");
  sub.add_option("--dataset", o->dataset,
                 "train on this data set (its train split and stats.h5, the config's frame selection) instead of "
                 "the synthetic scene")
      ->check(CLI::ExistingDirectory);
  return [o] { return run_bench_train(*o); };
});
