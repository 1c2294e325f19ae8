#pragma once
// Training and inference step of the model against the PyTorch reference (`layersnet bench model`).
#include <string>
#include <vector>

namespace layersnet::eval {

struct BenchModelOptions {
  std::string size = "small";
  std::string threads = "1,2";
  int passes = 2;
  int iters = 5;
  int warmup = 2;
  std::string reference;  // layersnet_torch.py; empty: time ours only
  std::string python = "/usr/bin/python3";
  double max_wait = 5;    // reference's quiet-machine wait per timing block, s
  bool no_reference = false;
  bool torch_filter = false;   // keep the reference's contention filter
  bool malloc_heap = true;     // mallopt as the reference's --malloc heap
  bool eigen_threads = false;  // let Eigen's GEMM use the OpenMP threads itself
  bool profile = false;  // per op kind: forward/backward time and tape bytes, train and infer step
  std::string json;
};

// Runs the benchmark and prints its table (and JSON when asked); returns the exit status.
// Throws std::invalid_argument, before any work, when --reference names no file.
int run_bench_model(const BenchModelOptions& options);

}  // namespace layersnet::eval
