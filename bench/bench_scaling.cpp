// `layersnet bench scaling`: rollout ms/frame and training step ms of one outfit re-meshed at
// several garment vertex counts, with the split of where the time goes.
//
// The outfit (bench_util.h): two open cylindrical garment sheets of fixed metric extent (inner
// 5.0 x 4.0, outer 6.25 x 4.75 scene units, radii 1.235 / 1.26) around a fixed body (106 x 65 =
// 6890 vertices, radius 1.2; the body never changes with the garment resolution). At a target N
// the garment spacing is h = sqrt(area / N). Patches come from the sheets' UVs at the model's
// patch size (ModelConfig defaults: 0.04 UV); two patch modes set the UV scale:
//   metric    patch = UV cell of fixed metric size (--patch-size, scene units): P constant,
//             only the per-vertex parts (input build, decoder) grow with N;
//   vertices  patch = --cell x --cell grid quads: P ∝ N, world neighbours of a patch grow too
//             (R is metric, patches shrink), so the attention rows grow faster than N.
// Model: ModelConfig defaults (the official sizes, which configs/default.toml keeps), random init.
//
// Per size and thread count: input build (dataset::build_sample + model::model_input_from_sample
// with the patch structure cached, as a rollout step; incl. neighbour search; the searches are
// also timed alone by re-running the same dataset/neighbours.h calls),
// forward stages (model::StageTimes), inference = input build + forward (no tape), training
// step = forward + losses + backward + Adam. Interleaved passes over all sizes (foreign load
// spreads over every size); medians over all passes' iterations after the first pass's warm-up.
#include "bench/bench_scaling.h"
#include "autodiff/optim.h"
#include "bench/bench_util.h"
#include "dataset/file_io.h"
#include "dataset/neighbours.h"
#include "losses/losses.h"
#include "losses/sample_loss_input.h"
#include "model/layersnet.h"
#include "model/params_layout.h"
#include "model/sample_input.h"

#include <Eigen/Core>
#include <nlohmann/json.hpp>
#include <omp.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <map>
#include <sstream>
#include <stdexcept>

namespace {


using namespace layersnet;
using eval::ScalingOptions;


using bench::kOutfit;
using bench::median;
using bench::median_times;
using bench::now_ms;
template <class T>
std::vector<T> parse_list(const std::string& list, const char* what) {
  std::vector<T> out;
  std::stringstream ss(list);
  std::string item;
  while (std::getline(ss, item, ',')) {
    if (item.empty()) continue;
    if constexpr (std::is_same_v<T, std::string>) {
      out.push_back(item);
    } else {
      const long v = std::stol(item);
      if (v < 1) throw std::runtime_error(std::string("bench scaling: ") + what + " '" + list + "' needs positive numbers");
      out.push_back(static_cast<T>(v));
    }
  }
  if (out.empty()) throw std::runtime_error(std::string("bench scaling: ") + what + " is empty");
  return out;
}

// The outfit at about `target` garment vertices (see the file comment), each sheet's UV step
// set so that a patch is o.cell x o.cell quads (vertices), or (metric) one of the
// round(extent / o.patch_size) cells that tile the sheet's extent: about o.patch_size units,
// the same count at every N.
bench::Scene make_outfit(int64_t target, const std::string& mode, const ScalingOptions& o, const ModelConfig& mc) {
  dataset::SyntheticOptions so = bench::outfit(target);
  if (mode != "metric" && mode != "vertices")
    throw std::runtime_error("bench scaling: --modes item '" + mode + "' is unknown; use metric and/or vertices");
  for (std::size_t g = 0; g < so.sheets.size(); ++g) {
    auto& sheet = so.sheets[g];
    if (mode == "vertices") {
      sheet.uv_step = {static_cast<float>(mc.patch_size / o.cell), static_cast<float>(mc.patch_size / o.cell)};
      continue;
    }
    const double extent[2] = {kOutfit[g].around, kOutfit[g].along};
    const int steps[2] = {sheet.around - 1, sheet.along - 1};
    for (int k = 0; k < 2; ++k) {
      const long cells = std::max(1L, std::lround(extent[k] / o.patch_size));
      sheet.uv_step[k] = static_cast<float>(mc.patch_size * static_cast<double>(cells) / steps[k]);
    }
  }
  return bench::make_scene(so, mc);
}

// The sample's neighbour searches alone (the same dataset/neighbours.h calls and sizes as
// build_sample, and the decoder candidates of model_input_from_sample).
struct SearchMs {
  double world = 0, body = 0, nearest = 0, candidates = 0;
  double total() const { return world + body + nearest + candidates; }
};
SearchMs time_searches(const dataset::TrainingSample& s, const ModelConfig& mc) {
  const dataset::Points centres = s.patch_state.leftCols<3>(), body = s.body_state.leftCols<3>();
  const dataset::Points x = s.state.leftCols<3>();
  const dataset::PatchStructure& all = s.structure->all;
  SearchMs ms;
  double t0 = now_ms();
  const auto w = dataset::world_edges(centres, all.adjacency, static_cast<float>(mc.world_radius));
  ms.world = now_ms() - t0;
  t0 = now_ms();
  const auto nb = dataset::body_neighbours(centres, body, model::sample_options_for(mc).neighbours);
  ms.body = now_ms() - t0;
  t0 = now_ms();
  const auto n1 = dataset::nearest_body(centres, body), n2 = dataset::nearest_body(x, body);
  ms.nearest = now_ms() - t0;
  t0 = now_ms();
  std::vector<double> xt(x.data(), x.data() + x.size()), centre(centres.data(), centres.data() + centres.size());
  std::vector<int32_t> co, ci;
  model::decoder_candidates(xt, centre, all.own_patch, all.adjacency.offsets, all.adjacency.items,
                            mc.decoder_patch_candidates, co, ci);
  ms.candidates = now_ms() - t0;
  if (w.items.size() + nb.hits.size() + n1.index.size() + n2.index.size() + ci.size() == 0) std::printf(" ");  // keep the work
  return ms;
}

struct Row {
  std::string mode;
  int threads = 1;
  int64_t N = 0, P = 0, B = 0, U = 0, E_world = 0, E_inter = 0, E_body = 0, E_mesh = 0, E_cand = 0;
  double h = 0, input_ms = 0, forward_ms = 0, infer_ms = 0;
  SearchMs search;
  model::StageTimes stages;  // medians, inference forward
  double train_ms = 0, train_forward_ms = 0, losses_ms = 0, backward_ms = 0, adam_ms = 0;
};


// One (mode, size): the scene, its input and loss target (built once), and the timings of
// every pass per thread count.
struct Samples {
  std::vector<double> input, fwd, infer, search[4], train, train_fwd, losses, backward, adam;
  std::vector<model::StageTimes> stages;
};
struct Case {
  std::string mode;
  double h = 0;
  bench::Scene scene;
  dataset::TrainingSample sample;  // at scene.t, for timing the searches alone
  model::ModelInput<float> input;
  losses::LossInput<float> target;
  int64_t U = 0;
  std::map<int, Samples> by_threads;
};

// `n` iterations of inference (input build + forward) and training steps at `threads`;
// the first `skip` are warm-up.
void measure(Case& c, const ModelConfig& mc, int threads, int skip, int n, bool train, ad::ParamStore<float>& ps,
             ad::Adam<float>& adam, ad::Tape<float>& tape) {
  omp_set_num_threads(threads);
  Eigen::setNbThreads(1);  // the ops own the threads (see bench model)
  Samples& s = c.by_threads[threads];
  for (int it = 0; it < skip + n; ++it) {
    const SearchMs sm = time_searches(c.sample, mc);
    const bench::InferenceTiming t = bench::time_inference(c.scene, mc, ps, tape);
    if (it >= skip) {
      s.input.push_back(t.input_ms), s.fwd.push_back(t.forward_ms), s.infer.push_back(t.input_ms + t.forward_ms);
      s.stages.push_back(t.stages);
      s.search[0].push_back(sm.world), s.search[1].push_back(sm.body), s.search[2].push_back(sm.nearest);
      s.search[3].push_back(sm.candidates);
    }
  }
  if (!train) return;
  LossConfig lc;
  for (int it = 0; it < skip + n; ++it) {
    const double t0 = now_ms();
    tape.reset();
    ps.zero_grads();
    const auto pred = model::forward(tape, ps, mc, c.input);
    const double t1 = now_ms();
    const auto terms = losses::compute_losses(tape, ps, mc, lc, c.target, pred);
    const double t2 = now_ms();
    tape.backward(terms.total);
    const double t3 = now_ms();
    adam.step();
    const double t4 = now_ms();
    if (it < skip) continue;
    s.train.push_back(t4 - t0), s.train_fwd.push_back(t1 - t0), s.losses.push_back(t2 - t1);
    s.backward.push_back(t3 - t2), s.adam.push_back(t4 - t3);
  }
}

Row summarise(const Case& c, int threads, const Samples& s) {
  Row r;
  r.mode = c.mode, r.threads = threads, r.h = c.h;
  r.input_ms = median(s.input), r.forward_ms = median(s.fwd), r.infer_ms = median(s.infer);
  r.search = {median(s.search[0]), median(s.search[1]), median(s.search[2]), median(s.search[3])};
  r.stages = median_times(s.stages);
  r.N = c.input.N, r.P = c.input.P, r.B = c.scene.seq.info.num_body_vertices, r.U = c.input.U;
  r.E_world = r.stages.world_rows, r.E_inter = r.stages.inter_rows, r.E_body = r.stages.body_rows;
  r.E_mesh = r.stages.mesh_rows, r.E_cand = r.stages.candidate_rows;
  r.train_ms = median(s.train), r.train_forward_ms = median(s.train_fwd), r.losses_ms = median(s.losses);
  r.backward_ms = median(s.backward), r.adam_ms = median(s.adam);
  return r;
}

// Cost ratio per doubling of N between two sizes: (y2 / y1)^(1 / log2(N2 / N1)).
double per_doubling(double y1, double y2, int64_t n1, int64_t n2) {
  const double k = std::log2(static_cast<double>(n2) / static_cast<double>(n1));
  return k > 0 && y1 > 0 ? std::pow(y2 / y1, 1.0 / k) : 0.0;
}
// Least-squares slope of log y against log N (1 = linear).
double loglog_slope(const std::vector<Row>& rows, double Row::*f) {
  double sx = 0, sy = 0, sxx = 0, sxy = 0, n = 0;
  for (const auto& r : rows) {
    if (r.*f <= 0) continue;
    const double x = std::log(static_cast<double>(r.N)), y = std::log(r.*f);
    sx += x, sy += y, sxx += x * x, sxy += x * y, n += 1;
  }
  const double d = n * sxx - sx * sx;
  return n > 1 && d != 0 ? (n * sxy - sx * sy) / d : 0.0;
}

void print_block(const std::vector<Row>& rows, bool train) {
  std::printf("%6s %5s %5s %6s %7s %7s %6s %7s | %7s %6s | %6s %6s %6s %6s %6s %6s %6s | %7s %5s",
              "N", "P", "U", "E_wld", "E_int", "E_mesh", "E_cand", "h", "input", "search", "graph", "enc", "attn",
              "edges", "ffn", "dec", "fwd", "infer", "x/dbl");
  if (train) std::printf(" | %7s %5s %6s %6s %6s %6s", "train", "x/dbl", "fwd", "loss", "bwd", "adam");
  std::printf("\n");
  for (std::size_t i = 0; i < rows.size(); ++i) {
    const Row& r = rows[i];
    const auto& s = r.stages;
    const double di = i ? per_doubling(rows[i - 1].infer_ms, r.infer_ms, rows[i - 1].N, r.N) : 0;
    std::printf("%6lld %5lld %5lld %6lld %7lld %7lld %6lld %7.4f | %7.1f %6.1f | %6.1f %6.1f %6.1f %6.1f %6.1f %6.1f %6.1f | %7.1f %4.2f%s",
                (long long)r.N, (long long)r.P, (long long)r.U, (long long)r.E_world, (long long)r.E_inter,
                (long long)r.E_mesh, (long long)r.E_cand, r.h, r.input_ms, r.search.total(), s.graph_ms, s.encoder_ms,
                s.attention_ms, s.attention_edges_ms, s.ffn_ms, s.decoder_ms, r.forward_ms, r.infer_ms, di,
                di > 2.2 ? "!" : " ");
    if (train) {
      const double dt = i ? per_doubling(rows[i - 1].train_ms, r.train_ms, rows[i - 1].N, r.N) : 0;
      std::printf(" | %7.1f %4.2f%s %6.1f %6.1f %6.1f %6.1f", r.train_ms, dt, dt > 2.2 ? "!" : " ", r.train_forward_ms,
                  r.losses_ms, r.backward_ms, r.adam_ms);
    }
    std::printf("\n");
  }
  std::printf("log-log slope (1 = linear): infer %.2f, forward %.2f, input %.2f", loglog_slope(rows, &Row::infer_ms),
              loglog_slope(rows, &Row::forward_ms), loglog_slope(rows, &Row::input_ms));
  if (train) std::printf(", train %.2f", loglog_slope(rows, &Row::train_ms));
  std::printf("\n");
}

nlohmann::json row_json(const Row& r) {
  const auto& s = r.stages;
  return {{"mode", r.mode}, {"threads", r.threads}, {"N", r.N}, {"P", r.P}, {"B", r.B}, {"U", r.U},
          {"spacing", r.h}, {"E_world", r.E_world}, {"E_inter", r.E_inter}, {"E_inter_body", r.E_body},
          {"E_mesh", r.E_mesh}, {"E_candidates", r.E_cand},
          {"input_ms", r.input_ms},
          {"search_ms", {{"world", r.search.world}, {"body", r.search.body}, {"nearest", r.search.nearest},
                         {"candidates", r.search.candidates}, {"total", r.search.total()}}},
          {"forward_ms", r.forward_ms}, {"infer_ms", r.infer_ms},
          {"stages_ms", {{"graph", s.graph_ms}, {"encoder", s.encoder_ms}, {"encoder_body", s.encoder_body_ms},
                         {"attention", s.attention_ms}, {"attention_edges", s.attention_edges_ms},
                         {"attention_inter", s.attention_inter_ms}, {"ffn", s.ffn_ms}, {"decoder", s.decoder_ms},
                         {"total", s.total_ms}}},
          {"train_ms", r.train_ms}, {"train_split_ms", {{"forward", r.train_forward_ms}, {"losses", r.losses_ms},
                                                        {"backward", r.backward_ms}, {"adam", r.adam_ms}}}};
}

void write_png(const std::string& path, const std::map<std::pair<std::string, int>, std::vector<Row>>& blocks, bool train) {
  if (!eval::gnuplot_available()) {
    std::printf("gnuplot not found (scripts/debian-packages.txt lists it): no PNG\n");
    return;
  }
  const std::string dat = path + ".dat";
  std::ofstream d(dat);
  std::string plot;
  int index = 0;
  double n0 = 0, y0 = 0, t0 = 0;
  double n_min = 1e300, n_max = 0;
  for (const auto& [key, rows] : blocks)
    for (const auto& r : rows) n_min = std::min(n_min, static_cast<double>(r.N)), n_max = std::max(n_max, static_cast<double>(r.N));
  for (const auto& [key, rows] : blocks) {
    d << "# " << key.first << " threads " << key.second << "\n";
    for (const auto& r : rows) d << r.N << " " << r.infer_ms << " " << r.train_ms << "\n";
    d << "\n\n";
    const std::string name = key.first + ", " + std::to_string(key.second) + " thr";
    const std::string lc = " lc " + std::to_string(index + 1);  // same colour for a block's two curves
    plot += "'" + dat + "' index " + std::to_string(index) + " using 1:2 with linespoints" + lc + " title 'infer " + name + "', ";
    if (train)
      plot += "'" + dat + "' index " + std::to_string(index) + " using 1:3 with linespoints dt 2" + lc + " title 'train " + name + "', ";
    // Reference lines through the lowest first point: a curve staying under its line grows at most linearly.
    if (!rows.empty() && (index == 0 || rows.front().infer_ms < y0))
      n0 = static_cast<double>(rows.front().N), y0 = rows.front().infer_ms;
    if (!rows.empty() && (index == 0 || rows.front().train_ms < t0)) t0 = rows.front().train_ms;
    ++index;
  }
  char ref[256];
  std::snprintf(ref, sizeof ref, "%g*x/%g with lines lc 'gray40' dt 3 title 'linear (through the lowest first infer point)'", y0, n0);
  plot += ref;
  if (train && t0 > 0) {
    std::snprintf(ref, sizeof ref, ", %g*x/%g with lines lc 'black' dt 3 title 'linear (through the lowest first train point)'", t0, n0);
    plot += ref;
  }
  const std::string script = path + ".gp";
  std::ofstream g(script);
  g << "set terminal pngcairo size 1000,750\nset output '" << path << "'\nset logscale xy\nset grid\n"
    << "set xlabel 'garment vertices N'\nset ylabel 'ms per frame / per training step'\n"
    << "set title 'LayersNet cost vs garment resolution (same outfit re-meshed)'\nset key left top inside font \",9\" box opaque\n"
    << "set xrange [" << 0.8 * n_min << ":" << 1.25 * n_max << "]\n"
    << "plot " << plot << "\n";
  g.close();
  d.close();
  if (!eval::run_gnuplot(script, script + ".log")) std::printf("gnuplot failed on %s (its output: %s.log)\n", script.c_str(), script.c_str());
  else
    std::printf("wrote %s (data %s, script %s)\n", path.c_str(), dat.c_str(), script.c_str());
}

}  // namespace

namespace layersnet::eval {

int run_bench_scaling(const ScalingOptions& o) {
  ad::keep_freed_memory_in_process();
  const auto sizes = parse_list<int64_t>(o.sizes, "--sizes");
  const auto threads = parse_list<int>(o.threads, "--threads");
  const auto modes = parse_list<std::string>(o.modes, "--modes");
  const ModelConfig mc;  // official sizes
  const char* wait = std::getenv("OMP_WAIT_POLICY");
  std::printf("bench scaling: sizes %s, threads %s, %d interleaved passes x %d iterations (+%d warm-up); model d=%d, %d layers, R=%g, R_b=%g, "
              "K=%d, decoder RET channels k=%d; body 6890 vertices fixed; OMP_WAIT_POLICY=%s\nload (uptime) at start: %s\n",
              o.sizes.c_str(), o.threads.c_str(), o.passes, o.iters, o.warmup, mc.width, mc.layers, mc.world_radius,
              mc.body_radius, mc.body_neighbors, mc.decoder_ret_channels, wait ? wait : "(default)", eval::load_averages().c_str());
  std::vector<Case> cases;
  double area = 0;
  for (const auto& g : kOutfit) area += g.around * g.along;
  for (const auto& mode : modes)
    for (int64_t n : sizes) {
      Case c;
      c.mode = mode, c.h = std::sqrt(area / static_cast<double>(n));
      c.scene = make_outfit(n, mode, o, mc);
      c.sample = bench::sample_of(c.scene, mc);
      c.input = model::model_input_from_sample(c.sample, c.scene.stats, mc);
      c.target = losses::loss_input_from_sample(c.sample, c.scene.seq.info);
      cases.push_back(std::move(c));
    }
  // One parameter set, optimiser and tape for every case (the tape's arena keeps the largest size).
  ad::ParamStore<float> ps;
  model::register_params(ps, mc);
  model::init_params(ps, mc, 1);
  ad::Adam<float> adam(ps, {.lr = 1e-6});  // tiny steps: the parameters stay near the initial ones
  ad::Tape<float> tape;
  // Interleaved: every pass visits every case, so foreign load spreads over all sizes.
  for (int pass = 0; pass < o.passes; ++pass) {
    for (auto& c : cases)
      for (int t : threads) measure(c, mc, t, pass == 0 ? o.warmup : 0, o.iters, !o.no_train, ps, adam, tape);
    std::printf("  pass %d of %d done (load %s)\n", pass + 1, o.passes, eval::load_averages().c_str());
    std::fflush(stdout);
  }
  std::map<std::pair<std::string, int>, std::vector<Row>> blocks;
  for (const auto& c : cases)
    for (const auto& [t, s] : c.by_threads) blocks[{c.mode, t}].push_back(summarise(c, t, s));
  std::printf("\nms per frame (medians). input = model input build incl. neighbour search; search = the searches "
              "alone (world, body, nearest, decoder candidates); graph/enc/attn/ffn/dec = forward stages (attn incl. "
              "edges); fwd = forward; infer = input + fwd; x/dbl = cost ratio per doubling of N vs the previous size "
              "(! > 2.2); train = forward + losses + backward + Adam\n");
  for (const auto& [key, rows] : blocks) {
    std::printf("\nmode %s (%s), threads %d\n", key.first.c_str(),
                key.first == "metric" ? ("patch " + std::to_string(o.patch_size) + " units: P constant").c_str()
                                      : (std::to_string(o.cell) + "x" + std::to_string(o.cell) + " quads per patch: P ∝ N").c_str(),
                key.second);
    print_block(rows, !o.no_train);
  }
  std::printf("\nload (uptime) at end: %s\n", eval::load_averages().c_str());
  if (!o.json.empty()) {
    nlohmann::json j = {{"sizes", sizes}, {"patch_size", o.patch_size}, {"cell", o.cell}, {"passes", o.passes}, {"iters", o.iters},
                        {"omp_wait_policy", wait ? wait : ""}, {"load_end", eval::load_averages()}, {"rows", nlohmann::json::array()}};
    for (const auto& [key, rows] : blocks)
      for (const auto& r : rows) j["rows"].push_back(row_json(r));
    layersnet::io::write_file_atomic(o.json, j.dump(1) + "\n");
  }
  if (!o.png.empty()) write_png(o.png, blocks, !o.no_train);
  return 0;
}

}  // namespace layersnet::eval

