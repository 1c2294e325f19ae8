// `layersnet bench scene`: options only; the benchmark is bench/bench_scene.h.
#include "cli/command_registry.h"
#include "bench/bench_scene.h"

#include <memory>

using layersnet::eval::SceneBenchOptions;
using layersnet::eval::run_bench_scene;

LAYERSNET_BENCH(scene, "Cost of each scene part: one vs two garments, wind, body near/far",
                [](CLI::App& sub) {
                  auto o = std::make_shared<SceneBenchOptions>();
                  sub.add_option("--vertices", o->vertices, "garment vertices of the full scene")->capture_default_str();
                  sub.add_option("--threads", o->threads, "OpenMP threads")->capture_default_str();
                  sub.add_option("--passes", o->passes, "interleaved passes over the configurations")->capture_default_str();
                  sub.add_option("--iters", o->iters, "iterations per configuration and pass")->capture_default_str();
                  sub.add_option("--warmup", o->warmup, "warm-up iterations (first pass)")->capture_default_str();
                  sub.add_option("--json", o->json, "write the figures as JSON");
                  return [o] { return run_bench_scene(*o); };
                });
