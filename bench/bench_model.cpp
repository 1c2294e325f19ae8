// `layersnet bench model`: our training step (forward + losses + backward + Adam) and inference
// step against the PyTorch reference (layersnet_torch.py, an outside file given by --reference;
// without it only ours is timed) on a synthetic scene of the same sizes and neighbour counts,
// in the same run, at each thread count.
//
// Neither side filters iterations by foreign load (see run_reference).
// Interleaving: for each pass and thread count we time our steps, then run the reference as a
// subprocess; the figure per side is the best (lowest) of the pass medians, as the reference's
// README advises on a shared machine. The load average is printed beside every row.
// GFLOP/s use the reference's FLOP count (`flops_forward.total`, train step = 3x forward), so
// FLOPs our formulation skips (e.g. the factored decoder) show up as a higher rate.
#include "bench/bench_model.h"
#include "autodiff/gemm_f32.h"
#include "autodiff/optim.h"
#include "bench/bench_util.h"
#include "dataset/file_io.h"
#include "losses/losses.h"
#include "losses/sample_loss_input.h"
#include "model/layersnet.h"
#include "model/params_layout.h"
#include "model/sample_input.h"

#include <Eigen/Core>
#include <nlohmann/json.hpp>
#include <omp.h>
#include <sys/resource.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>
#include <stdexcept>

namespace {


using namespace layersnet;
using eval::BenchModelOptions;
namespace fs = std::filesystem;


// The reference's SIZES (layersnet_torch.py): same grids, cells (3 x 4 quads per patch at the
// config's patch size), spacing, radii, heights.
dataset::SyntheticOptions reference_scene(const std::string& size, const ModelConfig& mc) {
  dataset::SyntheticOptions o;
  std::array<int, 2> inner, outer, body;  // (around, along) vertices
  if (size == "small") {
    inner = outer = {40, 25};
    body = {100, 40};
  } else if (size == "dlayers") {
    inner = {100, 80}, outer = {125, 96};
    body = {106, 65};
  } else {
    throw std::runtime_error("bench model: --size '" + size + "' is unknown; use small or dlayers");
  }
  o.frames = 6;
  const std::array<float, 2> step = {static_cast<float>(mc.patch_size / 3), static_cast<float>(mc.patch_size / 4)};
  o.sheets = {{inner[0], inner[1], 1.235f, 0.f, step}, {outer[0], outer[1], 1.26f, -0.2f, step}};
  o.sheet_spacing = 0.05f;
  float zmax = 0;
  for (const auto& g : o.sheets) zmax = std::max(zmax, g.z0 + (g.along - 1) * o.sheet_spacing);
  o.body_segments = body[0];
  o.body_rings = body[1];
  o.body_radius = 1.2f;
  o.body_bottom = -0.6f;
  o.height = zmax + 1.2f;
  o.body_caps = false;
  o.wind = true;
  o.seed = 0;
  return o;
}

using bench::median;
using bench::now_ms;
double vm_hwm_mib() {
  std::ifstream f("/proc/self/status");
  std::string line;
  while (std::getline(f, line))
    if (line.rfind("VmHWM:", 0) == 0) return std::stod(line.substr(6)) / 1024.0;
  rusage ru{};
  getrusage(RUSAGE_SELF, &ru);
  return ru.ru_maxrss / 1024.0;
}
std::vector<int> parse_threads(const std::string& list) {
  std::vector<int> out;
  std::stringstream ss(list);
  std::string item;
  while (std::getline(ss, item, ',')) {
    const int t = std::stoi(item);
    if (t < 1) throw std::runtime_error("bench model: --threads '" + list + "' needs positive counts, e.g. 1,2");
    out.push_back(t);
  }
  return out;
}
// What the reference is and where it comes from, for the one-line messages about it.
constexpr const char* kReferenceOrigin =
    "layersnet_torch.py is the PyTorch port of the official LayersNet (github.com/ftbabi/LayersNet_ICCV2023) "
    "that the speed ratios compare with, an outside reference distributed beside this repository, not in it "
    "(model/README.md, \"Speed against the PyTorch reference\")";

struct Ours {
  std::vector<double> train_ms, infer_ms, gemm_gflops;
};

// ---- the reference's BLAS
// OpenBLAS picks its kernel when it loads and takes an older one for a CPU newer than itself:
// Debian 12's 0.3.21 ran an AMD Zen 5 on its AVX2 Haswell kernel and an Intel Emerald Rapids on
// Prescott's SSE3 one, 12.8 GF/s where its SkylakeX kernel gives 135. A ratio against that
// measures the library's age, so the reference runs on the fastest kernel this CPU can run.
struct ReferenceBlas {
  std::string forced;   // OPENBLAS_CORETYPE the reference runs with; empty: the library's choice
  std::string how;      // "fastest of the probes", "OPENBLAS_CORETYPE", "library's choice", "--reference-blas"
  eval::BlasProbe chosen;
  std::vector<std::pair<std::string, eval::BlasProbe>> probes;  // (forced core or "", what it gave)
};

// One rows x 268 by 268 x 268 float32 product in the reference's python at 1 thread, the shape
// gemm_rate times ours on; median of 21 after 8 untimed (the first few run at a third of the
// rate: measured 27-32 against 95-190 GF/s on an AMD EPYC). The product goes into a buffer made
// once: a fresh 80,000-row output each time costs more in page faults than the product itself
// (27 GF/s against 163 with the same kernel, measured).
eval::BlasProbe probe_reference_blas(const BenchModelOptions& o, const std::string& core, Eigen::Index rows) {
  const fs::path out = fs::temp_directory_path() / ("layersnet_bench_blas_" + std::to_string(::getpid()) + ".txt");
  std::ostringstream cmd;
  cmd << "OPENBLAS_VERBOSE=2 ";
  if (!core.empty()) cmd << "OPENBLAS_CORETYPE=" << core << " ";
  cmd << o.python << " -c \"import time, torch; torch.set_num_threads(1); "
      << "a = torch.randn(" << rows << ", 268); b = torch.randn(268, 268); c = torch.empty(" << rows << ", 268); "
      << "[torch.mm(a, b, out=c) for _ in range(8)]; ts = []\n"
      << "for _ in range(21): t = time.perf_counter(); torch.mm(a, b, out=c); ts.append(time.perf_counter() - t)\n"
      << "print('gemm_gflops', 2.0 * " << rows << " * 268 * 268 / sorted(ts)[10] / 1e9)\" > " << out.string()
      << " 2>&1";
  const int rc = std::system(cmd.str().c_str());
  std::ifstream f(out);
  std::stringstream text;
  text << f.rdbuf();
  fs::remove(out);
  eval::BlasProbe p = eval::parse_blas_probe(text.str());
  if (rc != 0) p.gflops = 0;  // a kernel the CPU cannot run ends the probe
  return p;
}

ReferenceBlas choose_reference_blas(const BenchModelOptions& o, Eigen::Index rows) {
  ReferenceBlas r;
  auto probe = [&](const std::string& core) {
    r.probes.emplace_back(core, probe_reference_blas(o, core, rows));
    return r.probes.back().second;
  };
  const char* env = std::getenv("OPENBLAS_CORETYPE");
  const bool env_set = env && *env;
  if (o.reference_blas == "default") {
    r.how = env_set ? "OPENBLAS_CORETYPE" : "library's choice", r.chosen = probe("");
  } else if (o.reference_blas != "auto") {
    r.how = "--reference-blas", r.forced = o.reference_blas, r.chosen = probe(o.reference_blas);
  } else {
    // A set OPENBLAS_CORETYPE is one of the candidates, not the answer: machines set it for
    // their own reasons (one here held Zen 5 to Haswell's kernel, at half SkylakeX's rate).
    r.how = "fastest of the probes", r.chosen = probe("");
    for (const std::string& core : eval::openblas_cores_for_this_cpu()) {
      const eval::BlasProbe p = probe(core);
      if (p.gflops > r.chosen.gflops * 1.05) r.forced = core, r.chosen = p;  // 5 %: the probes' noise
    }
  }
  return r;
}

// A GEMM of the decoder's shape (rows x 268 by 268 x 268) on the float32 kernel the model's
// linear layers run (autodiff/gemm_f32.h: ours or Eigen's) on `threads` threads, GFLOP/s;
// median of 5 after 3.
double gemm_rate(Eigen::Index rows, int threads) {
  const Eigen::Index k = 268;
  using RowMajor = Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
  RowMajor a = RowMajor::Random(rows, k), b = RowMajor::Random(k, k), c(rows, k);
  const ad::F32GemmKernel kernel = ad::f32_gemm_kernel();
  const bool own = kernel != ad::F32GemmKernel::kEigen;
  std::vector<double> ts;
  for (int r = 0; r < 8; ++r) {
    const double t0 = now_ms();
    if (own) {
#pragma omp parallel num_threads(threads)
      {
        const Eigen::Index t = omp_get_thread_num(), n = omp_get_num_threads();
        const Eigen::Index r0 = rows * t / n, r1 = rows * (t + 1) / n;
        ad::gemm_f32(kernel, r1 - r0, k, k, a.data() + r0 * k, k, 1, b.data(), k, c.data() + r0 * k, k, true);
      }
    } else {
      Eigen::setNbThreads(threads);
      c.noalias() = a * b;
    }
    if (r >= 3) ts.push_back(now_ms() - t0);
  }
  Eigen::setNbThreads(1);  // the model's products thread by rows themselves
  return 2.0 * rows * k * k / (median(ts) * 1e-3) / 1e9;
}

struct Reference {
  bool ok = false;
  double train_ms = 0, infer_ms = 0, flops = 0, peak_mib = 0;
  nlohmann::json scene, raw;
};

Reference run_reference(const BenchModelOptions& o, const ReferenceBlas& blas, const fs::path& script, int threads) {
  Reference r;
  const fs::path out = fs::temp_directory_path() / ("layersnet_bench_model_" + std::to_string(::getpid()) + ".json");
  // The reference keeps only iterations with < 0.1 foreign cores and fails (empty median) when
  // every breakdown iteration is contended, which is the rule on a machine shared with other
  // jobs. Unless --torch-filter, it runs with the filter off (FOREIGN_MAX = inf), timed
  // like ours: plain medians, no waiting.
  std::ostringstream args;
  args << "'--size', '" << o.size << "', '--threads', '" << threads << "', '--iters', '" << o.iters
       << "', '--warmup', '" << o.warmup << "', '--max-wait', '" << o.max_wait << "', '--json', '" << out.string()
       << "'";
  std::ostringstream cmd;
  if (!blas.forced.empty()) cmd << "OPENBLAS_CORETYPE=" << blas.forced << " ";
  cmd << o.python << " -c \"import sys; sys.path.insert(0, '" << script.parent_path().string()
      << "'); import " << script.stem().string() << " as L; "
      << (o.torch_filter ? "" : "L.FOREIGN_MAX = float('inf'); ") << "sys.argv = ['" << script.filename().string()
      << "', " << args.str() << "]; L.main()\" > /dev/null 2>&1";
  const int rc = std::system(cmd.str().c_str());
  std::ifstream f(out);
  if (rc != 0 || !f) {
    std::fprintf(stderr, "bench model: the reference failed (exit %d): %s\n", rc, cmd.str().c_str());
    return r;
  }
  f >> r.raw;
  fs::remove(out);
  r.ok = true;
  r.train_ms = r.raw["timing"]["train_step"]["median_ms"].get<double>();
  r.infer_ms = r.raw["timing"]["rollout_step"]["median_ms"].get<double>();
  r.flops = r.raw["flops_forward"]["total"].get<double>();
  r.peak_mib = r.raw["peak_rss_mib"].get<double>();
  r.scene = r.raw["scene"];
  return r;
}

// Per op kind, summed over `iters` steps then divided by it: one training step's forward and
// backward and one inference step's forward, with the bytes each op kind allocates.
struct StepProfile {
  ad::TapeProfile train, infer;
  double train_ms = 0, infer_ms = 0;  // the profiled steps' own wall time (profiling on)
  double peak_rss_mib = 0;            // VmHWM after them
};

void print_profile(const StepProfile& p, int threads, const std::string& size) {
  const double mib = 1.0 / (1024.0 * 1024.0);
  std::printf("\nprofile --size %s, %d thread%s (per step; fwd = wall time from the previous op's end, "
              "model code in between included; arena = values + saved intermediates, held to the end of "
              "the step; grad = output gradients, committed only while backward needs them)\n",
              size.c_str(), threads, threads > 1 ? "s" : "");
  std::printf("%-16s | %5s %9s %9s %9s %9s | %5s %9s %9s\n", "op", "n", "fwd_ms", "bwd_ms", "arena_MiB", "grad_MiB",
              "n", "fwd_ms", "arena_MiB");
  std::printf("%-16s | %45s | %25s\n", "", "training step", "inference step");
  double tf = 0, tb = 0, ta = 0, tg = 0, itf = 0, ita = 0;
  int64_t tn = 0, itn = 0;
  for (int k = 0; k < ad::kOpCount; ++k) {
    const auto& a = p.train.ops[static_cast<std::size_t>(k)];
    const auto& b = p.infer.ops[static_cast<std::size_t>(k)];
    if (a.count == 0 && b.count == 0) continue;
    std::printf("%-16s | %5lld %9.2f %9.2f %9.1f %9.1f | %5lld %9.2f %9.1f\n", ad::op_name(static_cast<ad::OpKind>(k)),
                static_cast<long long>(a.count), a.forward_ms, a.backward_ms, a.arena_bytes * mib, a.grad_bytes * mib,
                static_cast<long long>(b.count), b.forward_ms, b.arena_bytes * mib);
    tn += a.count, tf += a.forward_ms, tb += a.backward_ms, ta += a.arena_bytes * mib, tg += a.grad_bytes * mib;
    itn += b.count, itf += b.forward_ms, ita += b.arena_bytes * mib;
  }
  std::printf("%-16s | %5lld %9.2f %9.2f %9.1f %9.1f | %5lld %9.2f %9.1f\n", "sum of ops", static_cast<long long>(tn),
              tf, tb, ta, tg, static_cast<long long>(itn), itf, ita);
  std::printf("%-16s | %35.2f %19s | %25.2f\n", "whole step", p.train_ms, "", p.infer_ms);
  std::printf("tape at the end of the training forward: arena %.1f MiB, gradients reserved %.1f MiB; "
              "process peak so far (VmHWM) %.0f MiB\n",
              p.train.arena_bytes_end_of_forward * mib, p.train.grad_bytes_reserved * mib, p.peak_rss_mib);
}

}  // namespace

namespace layersnet::eval {

BlasProbe parse_blas_probe(const std::string& output) {
  BlasProbe p;
  std::istringstream in(output);
  std::string line;
  while (std::getline(in, line)) {
    std::istringstream words(line);
    std::string key, value;
    words >> key >> value;
    if (key == "Core:") p.core = value;
    if (key == "gemm_gflops" && !value.empty()) {
      char* end = nullptr;
      const double rate = std::strtod(value.c_str(), &end);
      if (end && *end == '\0' && std::isfinite(rate) && rate > 0) p.gflops = rate;
    }
  }
  return p;
}

std::vector<std::string> openblas_cores_for_this_cpu() {
  std::ifstream f("/proc/cpuinfo");
  std::string line;
  std::set<std::string> flags;
  while (std::getline(f, line))
    if (line.rfind("flags", 0) == 0) {
      std::istringstream words(line.substr(line.find(':') + 1));
      for (std::string w; words >> w;) flags.insert(w);
      break;
    }
  auto has = [&](std::initializer_list<const char*> need) {
    return std::all_of(need.begin(), need.end(), [&](const char* n) { return flags.count(n) > 0; });
  };
  std::vector<std::string> cores;
  if (has({"avx2", "fma"})) cores.push_back("Haswell");
  if (has({"avx2", "fma", "avx512f", "avx512bw", "avx512vl", "avx512dq", "avx512cd"})) {
    cores.push_back("SkylakeX");
    if (has({"avx512_bf16"})) cores.push_back("Cooperlake");
    if (has({"avx512_bf16", "amx_tile", "amx_bf16"})) cores.push_back("SapphireRapids");
  }
  return cores;
}

int run_bench_model(const BenchModelOptions& o) {
  // The product's malloc tuning, which is also the reference's default (--malloc heap); perf:
  // ~17 % of a small-scene training step was page faults, clear_page and munmap without it.
  if (o.malloc_heap) ad::keep_freed_memory_in_process();
  // Checked before any work: a wrong path should not cost a benchmark run.
  const bool with_ref = !o.no_reference && !o.reference.empty();
  if (with_ref && !fs::is_regular_file(o.reference))
    throw std::invalid_argument("bench model: --reference " + o.reference + " is missing: " + kReferenceOrigin +
                          "; pass the path of your copy, or --no-reference");
  if (!o.no_reference && !with_ref)
    std::printf("bench model: timing ours only (no --reference; %s)\n", kReferenceOrigin);
  const fs::path script = o.reference;
  ModelConfig mc;  // official sizes
  mc.body_query = "first";  // the reference's ball query: first K body vertices in index order
  mc.decoder_ret_channels = 1;  // the reference's rank-3 decoder map (same FLOPs and parameters)
  LossConfig lc;
  const bench::Scene scene = bench::make_scene(reference_scene(o.size, mc), mc);
  // The input as a rollout step builds it (sample with its neighbour searches, model input).
  const double t_build0 = now_ms();
  const dataset::TrainingSample sample = bench::sample_of(scene, mc);
  const auto in = model::model_input_from_sample(sample, scene.stats, mc);
  const double build_ms = now_ms() - t_build0;
  const auto target = losses::loss_input_from_sample(sample, scene.seq.info);
  ad::ParamStore<float> ps;
  model::register_params(ps, mc);
  model::init_params(ps, mc, 1);
  ad::Adam<float> adam(ps, {.lr = 1e-3});
  ad::Tape<float> tape;

  const int64_t tokens_extra = 1 + (in.has_wind ? 1 : 0);  // gravity (+ wind) per patch
  // Counted as the reference does: U = distinct body vertices of the patch body lists (ours
  // also has tokens for the decoder's nearest vertices: U_all); E_mesh includes each patch's
  // attribute token.
  std::vector<int32_t> body_ids(in.body_tokens.begin(), in.body_tokens.end());
  std::sort(body_ids.begin(), body_ids.end());
  const auto u_lists = std::unique(body_ids.begin(), body_ids.end()) - body_ids.begin();
  nlohmann::json ours_scene = {{"N", in.N},
                               {"P", in.P},
                               {"A", in.A},
                               {"Nb", scene.seq.info.num_body_vertices},
                               {"U", u_lists},
                               {"U_all", in.U},
                               {"E_world", in.world_senders.size()},
                               {"E_mesh", static_cast<int64_t>(in.mesh_senders.size()) + in.P},
                               {"E_inter", static_cast<int64_t>(in.body_tokens.size()) + tokens_extra * in.P},
                               {"cand_valid_mean", static_cast<double>(in.cand_patches.size()) / in.N}};

  auto train_step = [&] {
    tape.reset();
    ps.zero_grads();
    const auto pred = model::forward(tape, ps, mc, in);
    const auto t = losses::compute_losses(tape, ps, mc, lc, target, pred);
    tape.backward(t.total);
    adam.step();
  };
  auto infer_step = [&] {
    tape.reset();
    ad::NoRecord<float> off(tape);
    model::forward(tape, ps, mc, in);
  };

  const auto threads = parse_threads(o.threads);
  if (o.profile)
    for (int t : threads) {
      omp_set_num_threads(t);
      Eigen::setNbThreads(o.eigen_threads ? t : 1);
      for (int i = 0; i < o.warmup; ++i) train_step(), infer_step();
      StepProfile sp;
      const int n = std::max(o.iters, 1);
      for (int i = 0; i < n; ++i) {
        tape.set_profile(&sp.train);
        double t0 = now_ms();
        train_step();
        sp.train_ms += now_ms() - t0;
        tape.set_profile(&sp.infer);
        t0 = now_ms();
        infer_step();
        sp.infer_ms += now_ms() - t0;
        tape.set_profile(nullptr);
      }
      for (ad::TapeProfile* tp : {&sp.train, &sp.infer})
        for (auto& op : tp->ops) op.count /= n, op.forward_ms /= n, op.backward_ms /= n, op.arena_bytes /= n, op.grad_bytes /= n;
      sp.train.arena_bytes_end_of_forward /= n, sp.train.grad_bytes_reserved /= n;
      sp.train_ms /= n, sp.infer_ms /= n;
      sp.peak_rss_mib = vm_hwm_mib();
      print_profile(sp, t, o.size);
    }
  if (o.passes <= 0) return 0;
  std::map<int, Ours> ours;
  std::map<int, std::vector<Reference>> refs;
  // libgomp reads OMP_WAIT_POLICY at start-up; the reference subprocess inherits it, so both
  // sides run under the same policy. On a loaded machine PASSIVE avoids spinning at barriers
  // for descheduled peers (small scene, 2 threads, load 7: train 130 ms vs 270-2800 ms).
  const char* wait_policy = std::getenv("OMP_WAIT_POLICY");
  std::printf("bench model --size %s: %d passes x (ours %d iters, reference %d iters) per thread count, "
              "input build %.1f ms, OMP_WAIT_POLICY=%s, float32 GEMM kernel %s\n",
              o.size.c_str(), o.passes, o.iters, o.iters, build_ms, wait_policy ? wait_policy : "(default)",
              ad::f32_gemm_kernel_name(ad::f32_gemm_kernel()));
  ReferenceBlas blas;
  if (with_ref) {
    const Eigen::Index rows = 8000;  // the kernels' order does not depend on the size
    blas = choose_reference_blas(o, rows);
    const double ours_gemm = gemm_rate(rows, 1);
    std::printf("reference BLAS: OpenBLAS kernel %s (%s), %.1f GF/s on the %lld x 268 GEMM at 1 thread, ours %.1f;",
                blas.chosen.core.empty() ? "(none reported)" : blas.chosen.core.c_str(), blas.how.c_str(),
                blas.chosen.gflops, static_cast<long long>(rows), ours_gemm);
    std::printf(" probed:");
    for (const auto& [core, p] : blas.probes)
      std::printf(" %s %.1f", core.empty() ? ("as set " + p.core).c_str() : core.c_str(), p.gflops);
    std::printf("\n");
    if (blas.chosen.gflops < 0.5 * ours_gemm)
      std::printf("bench model: the reference's BLAS runs at %.2fx our GEMM rate, so the ratios below measure its "
                  "BLAS more than its model; set OPENBLAS_CORETYPE to a kernel this CPU runs faster "
                  "(OpenBLAS's list: Haswell, SkylakeX, Cooperlake, SapphireRapids, Zen)\n",
                  ours_gemm > 0 ? blas.chosen.gflops / ours_gemm : 0.0);
  }
  for (int pass = 0; pass < o.passes; ++pass)
    for (int t : threads) {
      omp_set_num_threads(t);
      // Eigen's own multi-threaded GEMM (outside the ops' OpenMP chunks) synchronises by
      // spinning: on a loaded 2-core machine a 2-thread step took 30x the 1-thread one (perf:
      // 75 % in Eigen's gemm run() and libgomp waits). The ops parallelise over row chunks with
      // single-threaded Eigen products, so Eigen's threading stays off unless --eigen-threads.
      Eigen::setNbThreads(o.eigen_threads ? t : 1);
      Ours& u = ours[t];
      std::vector<double> tr, inf;
      for (int i = 0; i < o.warmup; ++i) train_step();
      for (int i = 0; i < o.iters; ++i) {
        const double t0 = now_ms();
        train_step();
        tr.push_back(now_ms() - t0);
      }
      for (int i = 0; i < o.warmup; ++i) infer_step();
      for (int i = 0; i < o.iters; ++i) {
        const double t0 = now_ms();
        infer_step();
        inf.push_back(now_ms() - t0);
      }
      u.train_ms.push_back(median(tr));
      u.infer_ms.push_back(median(inf));
      u.gemm_gflops.push_back(gemm_rate(std::max<Eigen::Index>(8000, 4 * in.N), t));
      std::printf("  pass %d threads %d: ours train %.1f ms infer %.1f ms (load %.2f)", pass + 1, t,
                  u.train_ms.back(), u.infer_ms.back(), eval::load_average_1min());
      if (with_ref) {
        refs[t].push_back(run_reference(o, blas, script, t));
        const auto& r = refs[t].back();
        if (r.ok) std::printf(" | torch train %.1f ms infer %.1f ms (load %.2f)", r.train_ms, r.infer_ms, eval::load_average_1min());
      }
      std::printf("\n");
      std::fflush(stdout);
    }

  // ---- scene side by side
  nlohmann::json ref_scene;
  for (const auto& [t, v] : refs)
    for (const auto& r : v)
      if (r.ok) ref_scene = r.scene;
  std::printf("\nscene          %10s %10s\n", "ours", "torch");
  for (const char* k : {"N", "P", "A", "Nb", "U", "U_all", "E_world", "E_mesh", "E_inter", "cand_valid_mean"}) {
    auto num = [](const nlohmann::json& j, const char* key) {
      return j.contains(key) ? j[key].get<double>() : -1.0;
    };
    std::printf("%-14s %10.6g %10.6g\n", k, num(ours_scene, k), num(ref_scene, k));
  }

  // ---- summary: best-of-pass medians
  const double peak = vm_hwm_mib();
  nlohmann::json out = {{"size", o.size}, {"omp_wait_policy", wait_policy ? wait_policy : ""}, {"scene_ours", ours_scene}, {"scene_torch", ref_scene},
                        {"input_build_ms", build_ms}, {"peak_rss_mib_ours", peak}, {"rows", nlohmann::json::array()}};
  out["f32_gemm_kernel"] = ad::f32_gemm_kernel_name(ad::f32_gemm_kernel());
  if (with_ref) {
    nlohmann::json probes = nlohmann::json::array();
    for (const auto& [core, p] : blas.probes)
      probes.push_back({{"openblas_coretype", core}, {"core", p.core}, {"gemm_gflops_1_thread", p.gflops}});
    out["reference_blas"] = {{"core", blas.chosen.core}, {"openblas_coretype", blas.forced}, {"chosen_by", blas.how},
                             {"gemm_gflops_1_thread", blas.chosen.gflops}, {"probes", probes}};
  }
  std::printf("\n%7s %10s %10s %7s %10s %10s %7s %9s %9s %9s %8s %9s %9s %6s\n", "threads", "train_ms", "torch_ms",
              "ratio", "infer_ms", "torch_ms", "ratio", "GF/s_trn", "GF/s_inf", "GEMM_GF/s", "trn/GEMM",
              "peak_MiB", "torch_MiB", "load");
  for (int t : threads) {
    const Ours& u = ours[t];
    const double tr = *std::min_element(u.train_ms.begin(), u.train_ms.end());
    const double inf = *std::min_element(u.infer_ms.begin(), u.infer_ms.end());
    const double gemm = *std::max_element(u.gemm_gflops.begin(), u.gemm_gflops.end());
    double rtr = 0, rinf = 0, flops = 0, rpeak = 0;
    for (const auto& r : refs[t])
      if (r.ok) {
        rtr = rtr == 0 ? r.train_ms : std::min(rtr, r.train_ms);
        rinf = rinf == 0 ? r.infer_ms : std::min(rinf, r.infer_ms);
        flops = r.flops, rpeak = std::max(rpeak, r.peak_mib);
      }
    const double gf_tr = flops > 0 ? 3 * flops / (tr * 1e-3) / 1e9 : 0, gf_inf = flops > 0 ? flops / (inf * 1e-3) / 1e9 : 0;
    // ratio > 1: we are faster
    const double s_tr = rtr > 0 ? rtr / tr : 0, s_inf = rinf > 0 ? rinf / inf : 0;
    std::printf("%7d %10.1f %10.1f %7.2f %10.1f %10.1f %7.2f %9.1f %9.1f %9.1f %8.2f %9.0f %9.0f %6.2f\n", t, tr, rtr,
                s_tr, inf, rinf, s_inf, gf_tr, gf_inf, gemm, gemm > 0 ? gf_tr / gemm : 0, peak, rpeak, eval::load_average_1min());
    out["rows"].push_back({{"threads", t},
                           {"train_ms", tr},
                           {"torch_train_ms", rtr},
                           {"train_speedup", s_tr},
                           {"infer_ms", inf},
                           {"torch_infer_ms", rinf},
                           {"infer_speedup", s_inf},
                           {"train_gflops", gf_tr},
                           {"infer_gflops", gf_inf},
                           {"gemm_gflops", gemm},
                           {"train_over_gemm", gemm > 0 ? gf_tr / gemm : 0},
                           {"infer_over_gemm", gemm > 0 ? gf_inf / gemm : 0},
                           {"torch_peak_rss_mib", rpeak},
                           {"passes_train_ms", u.train_ms},
                           {"passes_infer_ms", u.infer_ms},
                           {"load_average", eval::load_average_1min()}});
  }
  std::printf("ratio = torch time / our time (> 1: we are faster); best-of-pass medians; GFLOP/s from the "
              "reference's FLOP count (train = 3 x forward); peak_MiB = our VmHWM (whole run)\n");
  if (!o.json.empty()) {
    layersnet::io::write_file_atomic(o.json, out.dump(1) + "\n");
  }
  return 0;
}

}  // namespace layersnet::eval

