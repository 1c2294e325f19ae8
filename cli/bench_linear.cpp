// `layersnet bench linear`: options only; the benchmark is bench/bench_linear.h.
#include "cli/command_registry.h"
#include "bench/bench_linear.h"

#include <memory>

using layersnet::eval::LinearBenchOptions;
using layersnet::eval::run_bench_linear;

LAYERSNET_BENCH(linear,
                "Linear layer forward/backward vs a plain Eigen GEMM, its bf16 inference forward (1 and 2 threads), "
                "one core's peak bf16 and float32 multiply-add rates, and the precision simulate --precision auto "
                "takes here",
                [](CLI::App& sub) {
  auto opts = std::make_shared<LinearBenchOptions>();
  sub.add_option("--threads", opts->threads, "comma-separated thread counts")->default_val("1,2");
  sub.add_option("--reps", opts->reps, "timed repetitions (median is shown)")->default_val(7)->check(CLI::PositiveNumber);
  sub.add_option("--warmup", opts->warmup, "untimed repetitions first")->default_val(2);
  sub.add_option("--json", opts->json, "also write the figures to this JSON file");
  sub.add_flag("--relu", opts->relu, "also time relu(linear(x)) as two ops against the fused linear_relu");
  return [opts] { return run_bench_linear(*opts); };
});
