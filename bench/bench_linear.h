#pragma once
// The linear layer forward/backward against a plain Eigen GEMM, and its bf16 inference forward (`layersnet bench linear`).
#include <string>
#include <vector>

namespace layersnet::eval {

struct LinearBenchOptions {
  std::string threads = "1,2";
  int reps = 7;
  int warmup = 2;
  std::string json;
  bool relu = false;
};

// Runs the benchmark and prints its table (and JSON when asked); returns the exit status.
int run_bench_linear(const LinearBenchOptions& options);

}  // namespace layersnet::eval
