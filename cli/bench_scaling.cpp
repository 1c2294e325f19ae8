// `layersnet bench scaling`: rollout ms/frame and training step ms of one outfit re-meshed at
// several garment vertex counts, with the split of where the time goes.
//
// The outfit: two open cylindrical garment grids of fixed metric extent (inner 5.0 x 4.0,
// outer 6.25 x 4.75 scene units, radii 1.235 / 1.26) around a fixed body (106 x 65 = 6890
// vertices, radius 1.2; the body never changes with the garment resolution). At a target N
// the garment spacing is h = sqrt(area / N). Two patch modes:
//   metric    patch = UV cell of fixed metric size (--patch-size, scene units): P constant,
//             only the per-vertex parts (input build, decoder) grow with N;
//   vertices  patch = --cell x --cell grid quads: P ∝ N, world neighbours of a patch grow too
//             (R is metric, patches shrink), so the attention rows grow faster than N.
// Model: ModelConfig defaults (the official sizes, which configs/default.toml keeps; its
// patch_size is a UV size of the data set path and does not apply here), random init.
//
// Per size and thread count: input build (model/input_builder.h, incl. neighbour search;
// the searches are also timed alone by re-running the same dataset/neighbours.h calls),
// forward stages (model::StageTimes), inference = input build + forward (no tape), training
// step = forward + losses + backward + Adam. Interleaved passes over all sizes (foreign load
// spreads over every size); medians over all passes' iterations after the first pass's warm-up.
#include "autodiff/optim.h"
#include "cli/bench_util.h"
#include "cli/command_registry.h"
#include "dataset/file_io.h"
#include "dataset/neighbours.h"
#include "losses/losses.h"
#include "model/input_builder.h"
#include "model/layersnet.h"
#include "model/params_layout.h"
#include "model/synthetic_scene.h"

#include <Eigen/Core>
#include <malloc.h>
#include <nlohmann/json.hpp>
#include <omp.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <functional>
#include <map>
#include <set>
#include <sstream>
#include <stdexcept>

namespace {

using namespace layersnet;

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

struct OutfitGarment {
  double around, along, radius, z0;  // extent (scene units), nominal radius, first row height
};
constexpr OutfitGarment kOutfit[2] = {{5.0, 4.0, 1.235, 0.0}, {6.25, 4.75, 1.26, -0.2}};

using bench::median;
using bench::median_times;
using bench::now_ms;
using bench::uptime_load;
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

// Patches from grid quads: quad (i, j) of garment g goes to cell_of(g, i, j); cells numbered
// densely per garment in (u, v) order (as model/synthetic_scene.cpp does for its fixed cells).
// Rewrites v2p, p2v, own_patch, mesh adjacency and patch_garment of `s`, whose faces must be
// the synthetic scene's (two per quad, garments in order, i-major).
using CellOf = std::function<std::array<int, 2>(int g, int i, int j)>;
void repatch(model::SceneWindow& s, const std::vector<std::array<int, 2>>& grids, const CellOf& cell_of) {
  std::vector<std::array<int, 3>> face_cell;  // (g, cu, cv) of every face
  for (int g = 0; g < static_cast<int>(grids.size()); ++g)
    for (int i = 0; i + 1 < grids[g][0]; ++i)
      for (int j = 0; j + 1 < grids[g][1]; ++j) {
        const auto c = cell_of(g, i, j);
        face_cell.push_back({g, c[0], c[1]}), face_cell.push_back({g, c[0], c[1]});
      }
  if (face_cell.size() * 3 != s.faces.size())
    throw std::runtime_error("bench scaling: repatch expects 2 faces per grid quad; the synthetic scene changed");
  std::set<std::array<int, 3>> cells(face_cell.begin(), face_cell.end());
  std::map<std::array<int, 3>, int32_t> id;
  s.patch_garment.clear();
  for (const auto& c : cells) id.emplace(c, static_cast<int32_t>(id.size())), s.patch_garment.push_back(c[0]);
  s.P = static_cast<int64_t>(id.size());
  std::vector<std::set<int32_t>> v2p(s.N), adj(s.P);
  for (std::size_t f = 0; f < face_cell.size(); ++f)
    for (int k = 0; k < 3; ++k) v2p[s.faces[3 * f + k]].insert(id[face_cell[f]]);
  for (std::size_t f = 0; f < s.faces.size(); f += 3)
    for (int k = 0; k < 3; ++k)
      for (int32_t pu : v2p[s.faces[f + k]])
        for (int32_t pw : v2p[s.faces[f + (k + 1) % 3]]) adj[pu].insert(pw), adj[pw].insert(pu);
  std::vector<std::vector<int32_t>> p2v(s.P);
  s.v2p_offsets.assign(1, 0), s.v2p_patches.clear(), s.own_patch.clear();
  for (int64_t v = 0; v < s.N; ++v) {
    for (int32_t p : v2p[v]) s.v2p_patches.push_back(p), p2v[p].push_back(static_cast<int32_t>(v));
    s.v2p_offsets.push_back(static_cast<int32_t>(s.v2p_patches.size()));
    s.own_patch.push_back(v2p[v].empty() ? -1 : *v2p[v].begin());
  }
  s.p2v_offsets.assign(1, 0), s.p2v_vertices.clear(), s.adj_offsets.assign(1, 0), s.adj_patches.clear();
  for (int64_t p = 0; p < s.P; ++p) {
    s.p2v_vertices.insert(s.p2v_vertices.end(), p2v[p].begin(), p2v[p].end());
    s.p2v_offsets.push_back(static_cast<int32_t>(s.p2v_vertices.size()));
    s.adj_patches.insert(s.adj_patches.end(), adj[p].begin(), adj[p].end());
    s.adj_offsets.push_back(static_cast<int32_t>(s.adj_patches.size()));
  }
}

// The outfit at about `target` garment vertices (see the file comment).
model::SceneWindow make_outfit(int64_t target, const std::string& mode, const ScalingOptions& o) {
  double area = 0, zmax = 0;
  for (const auto& g : kOutfit) area += g.around * g.along, zmax = std::max(zmax, g.z0 + g.along);
  const double h = std::sqrt(area / static_cast<double>(target));
  model::SyntheticSceneOptions so;
  so.garments.clear();
  for (const auto& g : kOutfit) {
    so.garments.push_back({static_cast<int>(std::lround(g.around / h)) + 1, static_cast<int>(std::lround(g.along / h)) + 1});
    so.garment_radius.push_back(g.radius), so.garment_z0.push_back(g.z0);
  }
  so.cell = {1 << 20, 1 << 20};  // one patch per garment here (cheap); repatch() below sets the real ones
  so.spacing = h;
  so.body = {106, 65};
  so.body_radius = 1.2;
  so.body_z = {-0.6, zmax + 0.6};
  so.wind = true;
  so.seed = 0;
  model::SceneWindow s = model::make_synthetic_scene(so);
  CellOf cell_of;
  if (mode == "metric") {
    cell_of = [&o, h](int g, int i, int j) {
      const int nu = std::max(1, static_cast<int>(std::lround(kOutfit[g].around / o.patch_size)));
      const int nv = std::max(1, static_cast<int>(std::lround(kOutfit[g].along / o.patch_size)));
      const int cu = std::min(nu - 1, static_cast<int>(std::floor((i + 0.5) * h / o.patch_size)));
      const int cv = std::min(nv - 1, static_cast<int>(std::floor((j + 0.5) * h / o.patch_size)));
      return std::array<int, 2>{cu, cv};
    };
  } else if (mode == "vertices") {
    cell_of = [&o](int, int i, int j) { return std::array<int, 2>{i / o.cell, j / o.cell}; };
  } else {
    throw std::runtime_error("bench scaling: --modes item '" + mode + "' is unknown; use metric and/or vertices");
  }
  repatch(s, so.garments, cell_of);
  return s;
}

// The input builder's neighbour searches alone (same dataset/neighbours.h calls and sizes).
struct SearchMs {
  double world = 0, body = 0, nearest = 0, candidates = 0;
  double total() const { return world + body + nearest + candidates; }
};
SearchMs time_searches(const model::SceneWindow& s, const ModelConfig& mc) {
  auto rel = [](const std::vector<double>& x, const double r[3]) {
    std::vector<double> o(x.size());
    for (std::size_t i = 0; i < x.size(); ++i) o[i] = x[i] - r[i % 3];
    return o;
  };
  auto pts = [](const std::vector<double>& x) {
    dataset::Points p(static_cast<Eigen::Index>(x.size() / 3), 3);
    for (std::size_t i = 0; i < x.size(); ++i) p(static_cast<Eigen::Index>(i / 3), static_cast<Eigen::Index>(i % 3)) = static_cast<float>(x[i]);
    return p;
  };
  const auto xt = rel(s.x_t, s.root[2]), b1 = rel(s.body_tp1, s.root[3]);
  std::vector<double> centre(3 * s.P, 0.0);
  for (int64_t p = 0; p < s.P; ++p) {
    const int32_t b = s.p2v_offsets[p], e = s.p2v_offsets[p + 1];
    for (int32_t k = b; k < e; ++k)
      for (int c = 0; c < 3; ++c) centre[3 * p + c] += xt[3 * s.p2v_vertices[k] + c] / (e - b);
  }
  SearchMs ms;
  double t0 = now_ms();
  const auto cp = pts(centre), bp = pts(b1), xp = pts(xt);
  dataset::Csr adjacency{s.adj_offsets, s.adj_patches};
  const auto w = dataset::world_edges(cp, adjacency, static_cast<float>(mc.world_radius));
  ms.world = now_ms() - t0;
  t0 = now_ms();
  dataset::NeighbourOptions no;
  no.body_radius = static_cast<float>(mc.body_radius);
  no.body_k = mc.body_neighbors;
  no.body_query = mc.body_query == "first" ? dataset::BodyQuery::kFirstInIndexOrder : dataset::BodyQuery::kNearest;
  no.official_padding = false;
  const auto nb = dataset::body_neighbours(cp, bp, no);
  ms.body = now_ms() - t0;
  t0 = now_ms();
  const auto n1 = dataset::nearest_body(cp, bp), n2 = dataset::nearest_body(xp, bp);
  ms.nearest = now_ms() - t0;
  t0 = now_ms();
  std::vector<int32_t> co, ci;
  model::decoder_candidates(xt, centre, s.own_patch, s.adj_offsets, s.adj_patches, mc.decoder_patch_candidates, co, ci);
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
  model::SceneWindow scene;
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
    const SearchMs sm = time_searches(c.scene, mc);
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
  r.N = c.input.N, r.P = c.input.P, r.B = c.scene.B, r.U = c.input.U;
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
  if (std::system("command -v gnuplot > /dev/null 2>&1") != 0) {
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
  if (std::system(("gnuplot '" + script + "'").c_str()) != 0)
    std::printf("gnuplot failed on %s\n", script.c_str());
  else
    std::printf("wrote %s (data %s, script %s)\n", path.c_str(), dat.c_str(), script.c_str());
}

int run_bench_scaling(const ScalingOptions& o) {
  mallopt(M_MMAP_MAX, 0), mallopt(M_TRIM_THRESHOLD, -1), mallopt(M_ARENA_MAX, 1);  // as bench model
  const auto sizes = parse_list<int64_t>(o.sizes, "--sizes");
  const auto threads = parse_list<int>(o.threads, "--threads");
  const auto modes = parse_list<std::string>(o.modes, "--modes");
  const ModelConfig mc;  // official sizes
  const char* wait = std::getenv("OMP_WAIT_POLICY");
  std::printf("bench scaling: sizes %s, threads %s, %d interleaved passes x %d iterations (+%d warm-up); model d=%d, %d layers, R=%g, R_b=%g, "
              "K=%d, decoder RET channels k=%d; body 6890 vertices fixed; OMP_WAIT_POLICY=%s\nload (uptime) at start: %s\n",
              o.sizes.c_str(), o.threads.c_str(), o.passes, o.iters, o.warmup, mc.width, mc.layers, mc.world_radius,
              mc.body_radius, mc.body_neighbors, mc.decoder_ret_channels, wait ? wait : "(default)", uptime_load().c_str());
  std::vector<Case> cases;
  double area = 0;
  for (const auto& g : kOutfit) area += g.around * g.along;
  for (const auto& mode : modes)
    for (int64_t n : sizes) {
      Case c;
      c.mode = mode, c.h = std::sqrt(area / static_cast<double>(n));
      c.scene = make_outfit(n, mode, o);
      const auto in64 = model::build_model_input(c.scene, mc);
      c.input = model::cast_input<float>(in64);
      c.target = losses::cast_loss_input<float>(losses::build_loss_input(c.scene, in64));
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
    std::printf("  pass %d of %d done (load %s)\n", pass + 1, o.passes, uptime_load().c_str());
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
  std::printf("\nload (uptime) at end: %s\n", uptime_load().c_str());
  if (!o.json.empty()) {
    nlohmann::json j = {{"sizes", sizes}, {"patch_size", o.patch_size}, {"cell", o.cell}, {"passes", o.passes}, {"iters", o.iters},
                        {"omp_wait_policy", wait ? wait : ""}, {"load_end", uptime_load()}, {"rows", nlohmann::json::array()}};
    for (const auto& [key, rows] : blocks)
      for (const auto& r : rows) j["rows"].push_back(row_json(r));
    layersnet::io::write_file_atomic(o.json, j.dump(1) + "\n");
  }
  if (!o.png.empty()) write_png(o.png, blocks, !o.no_train);
  return 0;
}

}  // namespace

LAYERSNET_BENCH(scaling, "Rollout and training cost vs garment resolution, with the stage split",
                [](CLI::App& sub) {
                  auto o = std::make_shared<ScalingOptions>();
                  sub.add_option("--sizes", o->sizes, "target garment vertex counts")->capture_default_str();
                  sub.add_option("--threads", o->threads, "comma-separated thread counts")->capture_default_str();
                  sub.add_option("--modes", o->modes, "patch modes: metric (P constant), vertices (P ∝ N)")
                      ->capture_default_str();
                  sub.add_option("--patch-size", o->patch_size, "metric mode: patch edge, scene units")->capture_default_str();
                  sub.add_option("--cell", o->cell, "vertices mode: grid quads per patch side")->capture_default_str();
                  sub.add_option("--passes", o->passes, "interleaved passes over all sizes")->capture_default_str();
                  sub.add_option("--iters", o->iters, "timed iterations per size and pass")->capture_default_str();
                  sub.add_option("--warmup", o->warmup, "warm-up iterations per size (first pass)")->capture_default_str();
                  sub.add_flag("--no-train", o->no_train, "inference only");
                  sub.add_option("--json", o->json, "write the figures as JSON");
                  sub.add_option("--png", o->png, "gnuplot PNG of ms vs N (log-log, linear reference)");
                  return [o] { return run_bench_scaling(*o); };
                });
