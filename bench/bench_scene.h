#pragma once
// Cost of each scene part: one or two garments, wind, body near or far (`layersnet bench scene`).
#include <string>
#include <vector>

namespace layersnet::eval {

struct SceneBenchOptions {
  int64_t vertices = 8000;
  int threads = 1;
  int passes = 3;
  int iters = 3;
  int warmup = 1;
  std::string json;
};

// Runs the benchmark and prints its table (and JSON/PNG when asked); returns the exit status.
int run_bench_scene(const SceneBenchOptions& options);

}  // namespace layersnet::eval
