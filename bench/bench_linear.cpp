// `layersnet bench linear`: the linear layer (autodiff/ops_dense.h) at LayersNet's shapes
// against a plain Eigen GEMM of the same shape, in the same run, at 1 and 2 threads.
//
// Reference: C.noalias() = A * Bᵀ over row-major maps, A (N, Cin), B (Cout, Cin).
// Ours:      linear(tape, x, W, b) recording (as in training: also zeroes the output's
//            gradient buffer), the same without recording (rollouts), and the node's
//            backward (dx, dW, db) via tape.backward_seeded().
// bf16:      linear without recording at MatmulPrecision::kBFloat16 (autodiff/bf16_gemm.h;
//            inference only): x and W rounded to bfloat16, float accumulation; the weights
//            are packed once (cache) and checked against the cache on every call, as in a
//            rollout. Its speed-up is fwd0 / bf16; its error is reported against float.
// Peak:      one core's multiply-adds a second in register-only loops of VDPBF16PS and of
//            VFMADD231PS, and the precision `simulate --precision auto` takes on this CPU.
// Goals: forward >= 0.8 of the GEMM rate, backward <= 2.2x the forward time.
#include "bench/bench_linear.h"
#include "autodiff/bf16_gemm.h"
#include "autodiff/ops_dense.h"
#include "dataset/file_io.h"
#include "eval/machine.h"

#include <Eigen/Core>
#include <nlohmann/json.hpp>
#include <omp.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <fstream>
#include <memory>
#include <random>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

namespace {

using namespace layersnet::ad;
using layersnet::eval::LinearBenchOptions;
using layersnet::eval::median;


struct Shape {
  int64_t n, cin, cout;
};

struct Result {
  Shape shape;
  int threads;
  double gemm_ms, fwd_ms, fwd_norecord_ms, bwd_ms;
  double min_fwd_rate = 0, min_bwd_over_fwd = 0;  // the same ratios from the fastest repetitions
  double relu_separate_ms = 0, relu_fused_ms = 0;  // linear + relu, forward + backward
  double bf16_ms = 0, min_bf16_speedup = 0;        // bf16 forward (no recording); fwd0 / bf16 of the fastest
  double bf16_rel_err = 0;                         // max |y_bf16 - y_float| / max |y_float|
  double cpu_fwd0_ms = 0, cpu_bf16_ms = 0;          // process CPU time (all threads), medians
};

// CPU time of the whole process (every thread), ms: less sensitive than wall time to other
// jobs on a shared machine (waiting for a core costs no CPU time; OpenMP waits passively).
double process_cpu_ms() {
  timespec t{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
  return 1e3 * static_cast<double>(t.tv_sec) + 1e-6 * static_cast<double>(t.tv_nsec);
}

template <class Fn>
double time_ms(Fn&& fn) {
  const auto t0 = std::chrono::steady_clock::now();
  fn();
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

std::vector<float> random_floats(int64_t n, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  std::vector<float> v(static_cast<std::size_t>(n));
  for (float& x : v) x = u(rng);
  return v;
}

Result bench_shape(const Shape& s, int threads, const LinearBenchOptions& o) {
  omp_set_num_threads(threads);
  Eigen::setNbThreads(threads);
  const std::vector<float> xs = random_floats(s.n * s.cin, 1), ws = random_floats(s.cout * s.cin, 2),
                           bs = random_floats(s.cout, 3), dys = random_floats(s.n * s.cout, 4);
  // Each repetition times the four variants back to back, so that a busy machine slows
  // all of them alike; medians are taken per variant.
  std::vector<float> c(static_cast<std::size_t>(s.n * s.cout));
  const ConstMatMap<float> A(xs.data(), s.n, s.cin), B(ws.data(), s.cout, s.cin);
  MatMap<float> C(c.data(), s.n, s.cout);
  // Ours: parameters as tape leaves (gradients wanted), x a leaf too (dx wanted, as for
  // every layer but the first).
  Tape<float> tape;
  auto setup = [&] {
    tape.reset();
    return std::array<Var<float>, 3>{tape.leaf(xs.data(), s.n, s.cin), tape.leaf(ws.data(), s.cout, s.cin),
                                     tape.leaf(bs.data(), 1, s.cout)};
  };
  std::vector<double> gemm, fwd, fwd0, bwd, relu_separate, relu_fused, bf16, cpu_fwd0, cpu_bf16;
  for (int rep = 0; rep < o.warmup + o.reps; ++rep) {
    const bool keep = rep >= o.warmup;
    const double t_gemm = time_ms([&] { C.noalias() = A * B.transpose(); });
    double t_fwd0, c_fwd0;
    {
      const auto v = setup();
      NoRecord<float> off(tape);
      const double c0 = process_cpu_ms();
      t_fwd0 = time_ms([&] { linear(tape, v[0], v[1], v[2]); });
      c_fwd0 = process_cpu_ms() - c0;
    }
    double t_bf16, c_bf16;
    {
      const auto v = setup();
      NoRecord<float> off(tape);
      MatmulPrecisionScope<float> low(tape, MatmulPrecision::kBFloat16);
      const double c0 = process_cpu_ms();
      t_bf16 = time_ms([&] { linear(tape, v[0], v[1], v[2]); });
      c_bf16 = process_cpu_ms() - c0;
    }
    const auto v = setup();
    Var<float> y;
    const double t_fwd = time_ms([&] { y = linear(tape, v[0], v[1], v[2]); });
    std::memcpy(y.grad, dys.data(), sizeof(float) * dys.size());
    const double t_bwd = time_ms([&] { tape.backward_seeded(); });
    if (keep) gemm.push_back(t_gemm), fwd.push_back(t_fwd), fwd0.push_back(t_fwd0), bwd.push_back(t_bwd), bf16.push_back(t_bf16),
                  cpu_fwd0.push_back(c_fwd0), cpu_bf16.push_back(c_bf16);
    if (o.relu) {  // relu(linear(x)) as two ops, then fused; forward + backward each
      for (bool fused : {false, true}) {
        const auto u = setup();
        const double t = time_ms([&] {
          const Var<float> h = fused ? linear_relu(tape, u[0], u[1], u[2]) : relu(tape, linear(tape, u[0], u[1], u[2]));
          std::memcpy(h.grad, dys.data(), sizeof(float) * dys.size());
          tape.backward_seeded();
        });
        if (keep) (fused ? relu_fused : relu_separate).push_back(t);
      }
    }
  }
  Result r{s, threads, median(gemm), median(fwd), median(fwd0), median(bwd)};
  const auto min_of = [](const std::vector<double>& v) { return *std::min_element(v.begin(), v.end()); };
  r.min_fwd_rate = min_of(gemm) / min_of(fwd);
  r.min_bwd_over_fwd = min_of(bwd) / min_of(fwd);
  r.bf16_ms = median(bf16);
  r.min_bf16_speedup = min_of(fwd0) / min_of(bf16);
  r.cpu_fwd0_ms = median(cpu_fwd0);
  r.cpu_bf16_ms = median(cpu_bf16);
  if (o.relu) r.relu_separate_ms = median(relu_separate), r.relu_fused_ms = median(relu_fused);
  // The result must be the GEMM's plus the bias (guards against timing a broken kernel).
  {
    NoRecord<float> off(tape);
    const auto v = setup();
    const Var<float> y = linear(tape, v[0], v[1], v[2]);
    const float err = (y.val() - (C.rowwise() + ConstMatMap<float>(bs.data(), 1, s.cout).row(0))).cwiseAbs().maxCoeff();
    if (!(err < 1e-3f)) throw std::runtime_error("bench linear: forward differs from the GEMM by " + std::to_string(err));
    MatmulPrecisionScope<float> low(tape, MatmulPrecision::kBFloat16);
    const Var<float> y16 = linear(tape, v[0], v[1], v[2]);
    r.bf16_rel_err = (y16.val() - y.val()).cwiseAbs().maxCoeff() / y.val().cwiseAbs().maxCoeff();
  }
  return r;
}

std::vector<int> parse_threads(const std::string& list) {
  std::vector<int> out;
  std::stringstream ss(list);
  for (std::string item; std::getline(ss, item, ',');) {
    const int t = std::stoi(item);
    if (t < 1) throw std::runtime_error("bench linear: --threads '" + list + "' needs positive counts, e.g. 1,2");
    out.push_back(t);
  }
  return out;
}

// The machine may be shared: say how busy it was (a load above the core count inflates
// every time, and the ratios get noisy).
void print_load(const char* when) {
  std::printf("load average %s: %.2f (1 min), %d cores\n", when, layersnet::eval::load_average_1min(), omp_get_num_procs());
}

}  // namespace

namespace layersnet::eval {

int run_bench_linear(const LinearBenchOptions& o) {
  print_load("before");
  const std::vector<Shape> shapes = {{80000, 268, 268}, {20000, 128, 128}};
  std::vector<Result> results;
  std::printf("bench linear: float, median of %d after %d warm-up; GEMM = Eigen C.noalias() = A * B^T (row-major)\n",
              o.reps, o.warmup);
  std::printf("fwd = linear() recording (incl. zeroing dy's buffer), fwd0 = without recording, bwd = dx + dW + db\n\n");
  std::printf("%-18s %3s | %8s %8s %8s %8s | %7s %7s %7s %7s | %8s %8s %8s | %5s %5s\n", "shape N x Cin>Cout", "thr", "gemm ms",
              "fwd ms", "fwd0 ms", "bwd ms", "GF gemm", "GF fwd", "GF fwd0", "GF bwd", "fwd/gemm", "fwd0/gem",
              "bwd/fwd", "min f/g", "b/f");
  for (int threads : parse_threads(o.threads)) {
    for (const Shape& s : shapes) {
      const Result r = bench_shape(s, threads, o);
      results.push_back(r);
      const double gf = 2e-6 * static_cast<double>(s.n * s.cin * s.cout);  // GFLOP * 1e3 (per ms)
      char name[32];
      std::snprintf(name, sizeof name, "%ldx%ld>%ld", static_cast<long>(s.n), static_cast<long>(s.cin),
                    static_cast<long>(s.cout));
      std::printf("%-18s %3d | %8.2f %8.2f %8.2f %8.2f | %7.1f %7.1f %7.1f %7.1f | %8.3f %8.3f %8.3f | %5.3f %5.3f\n", name, threads,
                  r.gemm_ms, r.fwd_ms, r.fwd_norecord_ms, r.bwd_ms, gf / r.gemm_ms, gf / r.fwd_ms,
                  gf / r.fwd_norecord_ms, 2 * gf / r.bwd_ms, r.gemm_ms / r.fwd_ms, r.gemm_ms / r.fwd_norecord_ms,
                  r.bwd_ms / r.fwd_ms, r.min_fwd_rate, r.min_bwd_over_fwd);
      std::fflush(stdout);
    }
  }
  std::printf("\ngoals: fwd/gemm (rate ratio) >= 0.8, bwd/fwd (time ratio) <= 2.2\n");
  std::printf("\nbf16 products (inference, kernel: %s) against the float forward without recording (fwd0);\n"
              "err = max |y_bf16 - y_float| / max |y_float|; goal fwd0/bf16 >= 1.5 at 1 thread;\n"
              "cpu = process CPU time of all threads (robust to other jobs: waiting for a core costs none)\n",
              bf16_kernel_name());
  std::printf("%-18s %3s | %8s %8s | %7s %7s | %9s %9s | %8s %8s %9s | %9s\n", "shape N x Cin>Cout", "thr", "fwd0 ms",
              "bf16 ms", "GF fwd0", "GF bf16", "fwd0/bf16", "min ratio", "cpu fwd0", "cpu bf16", "cpu ratio", "err");
  for (const Result& r : results) {
    const double gf = 2e-6 * static_cast<double>(r.shape.n * r.shape.cin * r.shape.cout);
    char name[32];
    std::snprintf(name, sizeof name, "%ldx%ld>%ld", static_cast<long>(r.shape.n), static_cast<long>(r.shape.cin),
                  static_cast<long>(r.shape.cout));
    std::printf("%-18s %3d | %8.2f %8.2f | %7.1f %7.1f | %9.3f %9.3f | %8.2f %8.2f %9.3f | %9.2e\n", name, r.threads,
                r.fwd_norecord_ms, r.bf16_ms, gf / r.fwd_norecord_ms, gf / r.bf16_ms, r.fwd_norecord_ms / r.bf16_ms,
                r.min_bf16_speedup, r.cpu_fwd0_ms, r.cpu_bf16_ms, r.cpu_fwd0_ms / r.cpu_bf16_ms, r.bf16_rel_err);
  }
  const DotRates rates = measure_dot_rates();
  const char* auto_precision = bf16_outruns_float32() ? "bf16" : "float32";
  if (rates.fma_gmacs > 0)
    std::printf("one core's peak, no memory: VDPBF16PS %.1f, VFMADD231PS %.1f 10^9 multiply-adds/s "
                "(bf16/float32 %.2f)\n",
                rates.bf16_gmacs, rates.fma_gmacs, rates.bf16_gmacs / rates.fma_gmacs);
  std::printf("simulate --precision auto here: %s\n", auto_precision);
  print_load("after");
  if (o.relu) {
    std::printf("\nrelu(linear(x)) forward + backward (the memcpy seeding dy included in both):\n");
    for (const Result& r : results)
      std::printf("  %ldx%ld>%ld thr %d: separate %.2f ms, fused linear_relu %.2f ms (%.3fx)\n",
                  static_cast<long>(r.shape.n), static_cast<long>(r.shape.cin), static_cast<long>(r.shape.cout),
                  r.threads, r.relu_separate_ms, r.relu_fused_ms, r.relu_separate_ms / r.relu_fused_ms);
  }
  if (!o.json.empty()) {
    nlohmann::ordered_json rows = nlohmann::ordered_json::array();
    for (const Result& r : results) {
      nlohmann::ordered_json row = {{"n", r.shape.n},
                                    {"cin", r.shape.cin},
                                    {"cout", r.shape.cout},
                                    {"threads", r.threads},
                                    {"gemm_ms", r.gemm_ms},
                                    {"forward_ms", r.fwd_ms},
                                    {"forward_norecord_ms", r.fwd_norecord_ms},
                                    {"backward_ms", r.bwd_ms},
                                    {"forward_rate_vs_gemm", r.gemm_ms / r.fwd_ms},
                                    {"forward_norecord_rate_vs_gemm", r.gemm_ms / r.fwd_norecord_ms},
                                    {"backward_over_forward", r.bwd_ms / r.fwd_ms},
                                    {"min_forward_rate_vs_gemm", r.min_fwd_rate},
                                    {"min_backward_over_forward", r.min_bwd_over_fwd},
                                    {"bf16_ms", r.bf16_ms},
                                    {"bf16_speedup_vs_forward_norecord", r.fwd_norecord_ms / r.bf16_ms},
                                    {"min_bf16_speedup", r.min_bf16_speedup},
                                    {"bf16_max_rel_error", r.bf16_rel_err},
                                    {"cpu_forward_norecord_ms", r.cpu_fwd0_ms},
                                    {"cpu_bf16_ms", r.cpu_bf16_ms}};
      if (o.relu) {
        row["relu_separate_ms"] = r.relu_separate_ms;
        row["relu_fused_ms"] = r.relu_fused_ms;
      }
      rows.push_back(row);
    }
    const nlohmann::ordered_json out = {
        {"bench", "linear"},
        {"reps", o.reps},
        {"bf16_kernel", bf16_kernel_name()},
        {"peak_gmacs", {{"vdpbf16ps", rates.bf16_gmacs}, {"vfmadd231ps", rates.fma_gmacs}}},
        {"auto_precision", auto_precision},
        {"results", rows}};
    layersnet::io::write_file_atomic(o.json, out.dump(2) + "\n");
  }
  return 0;
}

}  // namespace layersnet::eval

