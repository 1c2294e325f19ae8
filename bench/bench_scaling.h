#pragma once
// Rollout and training cost against garment resolution, with the stage split (`layersnet bench scaling`).
#include <string>
#include <vector>

namespace layersnet::eval {

struct ScalingOptions {
  std::string sizes = "1000,2000,4000,8000,16000,32000";
  std::string threads = "1,2";
  std::string modes = "metric,vertices";
  double patch_size = 0.25;  // metric mode: patch edge, scene units (~10 vertices per patch at N = 8000)
  int cell = 3;              // vertices mode: quads per patch side (16 vertices incl. borders)
  int passes = 2;
  int iters = 2;
  int warmup = 1;
  bool no_train = false;
  std::string json, png;
};

// Runs the benchmark and prints its table (and JSON/PNG when asked); returns the exit status.
int run_bench_scaling(const ScalingOptions& options);

}  // namespace layersnet::eval
