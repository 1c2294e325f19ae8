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
  // The reference's OpenBLAS kernel (OPENBLAS_CORETYPE): "auto" probes the kernel the
  // environment gives (the library's choice, or OPENBLAS_CORETYPE when set) and every kernel this
  // CPU can run, and keeps the fastest; "default" keeps the environment's; any other value is
  // passed on as the kernel's name.
  std::string reference_blas = "auto";
  std::string json;
};

// What a probe of the reference's BLAS printed: OpenBLAS's "Core: <name>" line (it prints it under
// OPENBLAS_VERBOSE=2) and the probe's "gemm_gflops <rate>" line; an empty core or a zero rate
// where the line is missing.
struct BlasProbe {
  std::string core;
  double gflops = 0;
};
BlasProbe parse_blas_probe(const std::string& output);

// OpenBLAS's x86-64 kernels whose instructions this CPU has, oldest first (empty elsewhere).
std::vector<std::string> openblas_cores_for_this_cpu();

// Runs the benchmark and prints its table (and JSON when asked); returns the exit status.
// Throws std::invalid_argument, before any work, when --reference names no file.
int run_bench_model(const BenchModelOptions& options);

}  // namespace layersnet::eval
