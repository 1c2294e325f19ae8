// `layersnet bench scaling`: options only; the benchmark is bench/bench_scaling.h.
#include "cli/command_registry.h"
#include "bench/bench_scaling.h"

#include <memory>

using layersnet::eval::ScalingOptions;
using layersnet::eval::run_bench_scaling;

LAYERSNET_BENCH(scaling, "Rollout and training cost vs garment resolution, with the stage split",
                [](CLI::App& sub) {
                  auto o = std::make_shared<ScalingOptions>();
                  sub.add_option("--sizes", o->sizes, "target garment vertex counts")->capture_default_str();
                  sub.add_option("--threads", o->threads, "comma-separated thread counts")->capture_default_str();
                  sub.add_option("--modes", o->modes, "patch modes: metric (P constant), vertices (P ∝ N)")
                      ->capture_default_str();
                  sub.add_option("--patch-size", o->patch_size, "metric mode: patch edge, scene units")->capture_default_str();
                  sub.add_option("--cell", o->cell, "vertices mode: grid quads per patch side")->capture_default_str();
                  sub.add_option("--passes", o->passes, "interleaved passes over all sizes")->capture_default_str();
                  sub.add_option("--iters", o->iters, "timed iterations per size and pass")->capture_default_str();
                  sub.add_option("--warmup", o->warmup, "warm-up iterations per size (first pass)")->capture_default_str();
                  sub.add_flag("--no-train", o->no_train, "inference only");
                  sub.add_option("--json", o->json, "write the figures as JSON");
                  sub.add_option("--png", o->png, "gnuplot PNG of ms vs N (log-log, linear reference)");
                  return [o] { return run_bench_scaling(*o); };
                });
