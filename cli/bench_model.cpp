// `layersnet bench model`: options only; the benchmark is bench/bench_model.h.
#include "cli/command_registry.h"
#include "cli/exit_codes.h"
#include "bench/bench_model.h"

#include <memory>
#include <stdexcept>

using layersnet::eval::BenchModelOptions;
using layersnet::eval::run_bench_model;

LAYERSNET_BENCH(model, "Training and inference step vs the PyTorch reference", [](CLI::App& sub) {
  auto o = std::make_shared<BenchModelOptions>();
  sub.add_option("--size", o->size, "reference scene: small or dlayers")->capture_default_str();
  sub.add_option("--threads", o->threads, "comma-separated thread counts")->capture_default_str();
  sub.add_option("--passes", o->passes, "interleaved passes (best-of-pass medians)")->capture_default_str();
  sub.add_option("--iters", o->iters, "timed iterations per pass and side")->capture_default_str();
  sub.add_option("--warmup", o->warmup, "warm-up iterations per pass and side")->capture_default_str();
  sub.add_option("--reference", o->reference, "the PyTorch reference layersnet_torch.py (not in this repository; without it only ours is timed)");
  sub.add_option("--python", o->python, "python with torch")->capture_default_str();
  sub.add_option("--max-wait", o->max_wait, "reference's quiet-machine wait per block, s")->capture_default_str();
  sub.add_flag("--no-reference", o->no_reference, "time ours only");
  sub.add_option("--reference-blas", o->reference_blas,
                 "the reference's OpenBLAS kernel: auto (the fastest of those this CPU runs, a set "
                 "OPENBLAS_CORETYPE among them), default (the environment's: OPENBLAS_CORETYPE or the "
                 "library's choice) or a kernel's name")
      ->capture_default_str();
  sub.add_flag("--torch-filter", o->torch_filter,
               "keep the reference's contention filter (drops iterations with foreign load; fails on a busy machine)");
  sub.add_option("--json", o->json, "write the figures as JSON");
  sub.add_flag("--profile", o->profile,
               "first print, per op kind, forward and backward time and tape bytes of one training and one "
               "inference step (mean of --iters; with --passes 0 only this)");
  sub.add_flag("--eigen-threads", o->eigen_threads, "Eigen's own GEMM threading on (default off)");
  sub.add_flag("!--default-malloc", o->malloc_heap, "do not tune malloc (reference: --malloc default)");
  return [o] {
    try {
      return run_bench_model(*o);
    } catch (const std::invalid_argument& e) {
      throw layersnet::cli::UsageError(e.what());  // a wrong path is a usage error (exit 2)
    }
  };
});
