// `layersnet inspect` (see inspect.h).
#include "inspect/inspect.h"

#include "autodiff/check.h"
#include "dataset/manifest.h"
#include "dataset/patches.h"
#include "dataset/sequence.h"
#include "dataset/stats.h"
#include "dataset/wind.h"
#include "eval/metrics.h"
#include "eval/rollout.h"
#include "losses/physics.h"
#include "run/cloth_constraints.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <iterator>
#include <cstdio>
#include <filesystem>
#include <limits>
#include <set>

namespace layersnet::eval {

using namespace dataset;

namespace {

// Signed distances (x - a)·n_a of garment vertices to their collision anchors, measured as the
// collision loss does: a = nearest body vertex (body term) or nearest inner-garment vertex
// (layer term, outer garment only), n_a its vertex normal. Training split, every frame after
// the ramp.
struct MarginTally {
  std::vector<float> body, layer;
  std::vector<float> stretch;  // edge length / rest length − 1, signed (garments with a rest shape)
  std::vector<float> fold;     // far-corner distance of adjacent triangles / its rest value − 1
  // Motion against the body by distance band (kSlipBands, scene units from the nearest body
  // vertex along its normal): vertex-frames, summed tangential slip |r − (r·n)n| with
  // r = (x_t − x_{t−1}) − (h_t − h_{t−1}), and summed body motion |h_t − h_{t−1}|.
  static constexpr float kSlipBands[] = {0.15f, 0.3f, 0.6f};
  std::array<double, 4> slip_count{}, slip_sum{}, body_motion_sum{};
  // layout: eval::garment_layout(info); inner_faces: eval::inner_faces(layout).
  void add_frame(const SequenceInfo& info, const GarmentLayout& layout, const Faces& inner_faces,
                 const FrameWindow& w, int t) {
    const Points body_x = w.body_at(t, info.num_body_vertices);
    Points x(layout.num_vertices(), 3);
    for (int k = 0; k < layout.num_garments(); ++k)
      x.middleRows(layout.offsets[k], info.garments[k].num_vertices) = w.garment_at(k, t, info.garments[k].num_vertices);
    const Points body_n = vertex_normals(body_x, info.body_faces);
    const NearestBody on_body = nearest_body(x, body_x);  // one search for the margins and the slip
    signed_distances(x, body_x, body_n, on_body, body);
    if (t > w.first) add_slip(info, layout, w, t, x, body_x, body_n, on_body);
    for (int k = 0; k < layout.num_garments(); ++k) {
      const GarmentMesh& g = info.garments[k];
      if (g.rest.rows() != g.num_vertices) continue;
      auto ratio = [&](int32_t a, int32_t b, std::vector<float>& out) {
        const float rest = (g.rest.row(a) - g.rest.row(b)).norm();
        if (rest > 0) out.push_back((x.row(layout.offsets[k] + a) - x.row(layout.offsets[k] + b)).norm() / rest - 1.f);
      };
      for (const auto& [a, b] : mesh_edges(g.faces)) ratio(a, b, stretch);
      for (const auto& [a, b] : far_corners(g.faces)) ratio(a, b, fold);
    }
    if (!layout.layered()) return;
    const Points inner = x.topRows(layout.num_vertices() - layout.outer_vertices());
    const Points outer = x.bottomRows(layout.outer_vertices());
    signed_distances(outer, inner, vertex_normals(inner, inner_faces), nearest_body(outer, inner), layer);
  }
  void add_slip(const SequenceInfo& info, const GarmentLayout& layout, const FrameWindow& w, int t, const Points& x,
                const Points& body_x, const Points& body_n, const NearestBody& nb) {
    const Points body_before = w.body_at(t - 1, info.num_body_vertices);
    for (int k = 0; k < layout.num_garments(); ++k) {
      const Points before = w.garment_at(k, t - 1, info.garments[k].num_vertices);
      for (int v = 0; v < info.garments[k].num_vertices; ++v) {
        const Eigen::Index i = layout.offsets[k] + v, h = nb.index[i];
        const Eigen::RowVector3f n = body_n.row(h);
        const Eigen::RowVector3f body_step = body_x.row(h) - body_before.row(h);
        const Eigen::RowVector3f r = (x.row(i) - before.row(v)) - body_step;
        const float d = (x.row(i) - body_x.row(h)).dot(n);
        const auto band = std::upper_bound(std::begin(kSlipBands), std::end(kSlipBands), d) - std::begin(kSlipBands);
        slip_count[band] += 1;
        slip_sum[band] += (r - r.dot(n) * n).norm();
        body_motion_sum[band] += body_step.norm();
      }
    }
  }
  void print_slip() const {
    double total = 0;
    for (double c : slip_count) total += c;
    if (total == 0) return;
    std::printf("ground-truth motion against the body per frame, by distance from it (eval.body_friction acts within "
                "eval.friction_distance), scene units:\n");
    for (std::size_t b = 0; b < slip_count.size(); ++b) {
      if (slip_count[b] == 0) continue;
      const float lo = b == 0 ? -std::numeric_limits<float>::infinity() : kSlipBands[b - 1];
      const float hi = b < std::size(kSlipBands) ? kSlipBands[b] : std::numeric_limits<float>::infinity();
      std::printf("  distance [%g, %g): %.1f%% of vertex-frames, tangential slip %.4f, body motion %.4f\n", lo, hi,
                  100.0 * slip_count[b] / total, slip_sum[b] / slip_count[b], body_motion_sum[b] / slip_count[b]);
    }
  }
  // nb: the nearest anchor of each row of x.
  static void signed_distances(const Points& x, const Points& anchors, const Points& normals, const NearestBody& nb,
                               std::vector<float>& out) {
    for (Eigen::Index i = 0; i < x.rows(); ++i)
      out.push_back((x.row(i) - anchors.row(nb.index[i])).dot(normals.row(nb.index[i])));
  }
  static void print_ratios(const char* what, std::vector<float> r) {
    if (r.empty()) return;
    std::sort(r.begin(), r.end());
    const std::vector<double> sorted(r.begin(), r.end());
    std::printf("ground-truth %s, %zu frames x pairs: percentiles", what, sorted.size());
    for (double q : {0.001, 0.01, 0.05, 0.5, 0.95, 0.99, 0.999})
      std::printf(" %g: %+.3f", 100 * q, quantile(sorted, q));
    std::printf("\n");
  }
  static void print(const char* what, std::vector<float> d) {
    if (d.empty()) {
      std::printf("  %s: no vertices\n", what);
      return;
    }
    std::sort(d.begin(), d.end());
    const std::vector<double> sorted(d.begin(), d.end());
    auto pct = [&](double q) { return quantile(sorted, q); };
    std::printf("  %s (%zu vertex-frames): percentiles 1/5/10/50 %.3f / %.3f / %.3f / %.3f; share closer than", what,
                d.size(), pct(0.01), pct(0.05), pct(0.10), pct(0.5));
    for (float eps : {0.001f, 0.01f, 0.03f, 0.05f, 0.06f, 0.1f}) {
      const auto n = std::lower_bound(d.begin(), d.end(), eps) - d.begin();
      std::printf(" %g: %.1f%%", eps, 100.0 * static_cast<double>(n) / static_cast<double>(d.size()));
    }
    std::printf("\n");
  }
};

// Outer-garment patches and their world edges to inner-garment patches, over sequences.
struct CrossGarmentTally {
  int64_t patches = 0, edges = 0, without = 0;
  int32_t min = std::numeric_limits<int32_t>::max();
  void add(const std::vector<int32_t>& counts) {
    for (int32_t c : counts) {
      ++patches, edges += c, without += c == 0;
      min = std::min(min, c);
    }
  }
  void print(const char* indent) const {
    if (patches == 0) {
      std::printf("%sno outer-garment patches (single-garment sequences)\n", indent);
      return;
    }
    std::printf("%s%ld outer-garment patches: %.3g cross-garment world edges each (min %d), %.1f%% with none\n", indent,
                static_cast<long>(patches), static_cast<double>(edges) / static_cast<double>(patches), min,
                100.0 * static_cast<double>(without) / static_cast<double>(patches));
  }
};

// The sample training would build at the sequence's first frame after the ramp (t >= 2 as
// every sample); its world edges depend on positions only, so any statistics do.
std::vector<int32_t> cross_garment_edges(const SequenceFile& f, const SampleOptions& options, int* frame) {
  const SequenceInfo& info = f.info();
  if (info.num_frames < 4) return {};  // too short for any sample
  *frame = std::clamp(info.settled_frame(), 2, info.num_frames - 2);
  const FrameWindow w = f.read_frames(*frame - 2, 4);
  return outer_to_inner_world_edges(build_sample(info, w, *frame, NormalisationStats{}, nullptr, options));
}

void print_wind(const SequenceInfo& info) {
  const auto segments = wind_segments(info);
  if (segments.empty()) {
    std::printf("    wind: none (no /wind group)\n");
    return;
  }
  std::printf("    wind: %zu segment(s):", segments.size());
  for (const auto& s : segments) {
    if (s.strength == 0.f)
      std::printf(" [%d,%d) calm;", s.begin, s.end);
    else
      std::printf(" [%d,%d) strength %.4g along (%.2f, %.2f, %.2f);", s.begin, s.end, s.strength, s.direction.x(),
                  s.direction.y(), s.direction.z());
  }
  std::printf("\n");
}

// Pinned vertices carried with the body from `first` to the last frame, each frame from the
// carried frame before (as in a rollout; the other vertices from the ground truth), against the
// ground truth's: distances in scene units, one per pinned vertex-frame.
std::vector<float> carried_pin_errors(const Sequence& seq, int first) {
  EvalConfig pins_only;
  pins_only.strain_limit = 0;
  pins_only.fold_limit = 0;
  pins_only.collision_shell = 0;
  pins_only.body_friction = 0;
  pins_only.layer_friction = 0;
  pins_only.pins = true;
  const ClothConstraints carry(seq.info, rest_garments(seq), seq.body_at(0), garments_at(seq, 0), pins_only);
  const std::vector<Eigen::Index> rows = seq.info.pinned_rows();
  std::vector<float> errors;
  if (rows.empty()) return errors;
  Points carried = garments_at(seq, first);
  for (int t = first; t + 1 < seq.info.num_frames; ++t) {
    const Points truth = garments_at(seq, t + 1);
    Points x = truth;
    carry.apply(seq.body_at(t + 1), x, seq.body_at(t), carried);
    for (Eigen::Index r : rows) errors.push_back((x.row(r) - truth.row(r)).norm());
    carried = std::move(x);
  }
  return errors;
}

// Pinned vertices rigged from the body from `first` on (dataset::rig_pins), against the ground
// truth's at every later frame: distances in scene units, one per pinned vertex-frame.
std::vector<float> rigged_pin_errors(const Sequence& seq, int first) {
  Sequence rigged = seq;
  rig_pins(rigged, first);
  const std::vector<Eigen::Index> rows = seq.info.pinned_rows();
  std::vector<float> errors;
  for (int t = first + 1; t < seq.info.num_frames && !rows.empty(); ++t) {
    const Points truth = garments_at(seq, t), x = garments_at(rigged, t);
    for (Eigen::Index r : rows) errors.push_back((x.row(r) - truth.row(r)).norm());
  }
  return errors;
}

// Normal equations of the stationarity fit: ‖g_inertia + Σ_k w_k g_k‖² over the free vertices of
// many frames, g the terms' gradients at Blender's x_{t+1}.
struct PhysicsBalance {
  static constexpr int kTerms = 7;
  static constexpr const char* kNames[kTerms] = {"drag", "stretch", "bending", "gravity", "wind", "body collision",
                                                 "layer collision"};
  Eigen::Matrix<double, kTerms, kTerms> gram = Eigen::Matrix<double, kTerms, kTerms>::Zero();
  Eigen::Matrix<double, kTerms, 1> cross = Eigen::Matrix<double, kTerms, 1>::Zero();  // −g_kᵀ g_inertia
  double inertia_sq = 0;
  int frames = 0;
  // Per free vertex-frame, each term's gradient length and the inertia's (index kTerms): the
  // median says what a typical vertex feels, the rms above is led by the worst vertices.
  std::array<std::vector<float>, kTerms + 1> vertex_norm;

  void add(const Sequence& seq, const std::shared_ptr<const SequenceStructure>& structure, int t) {
    const TrainingSample s = build_sample(seq.info, seq.frames, t, NormalisationStats{}, structure);
    const losses::PhysicsSettings settings;
    const auto in = losses::cast_physics_input<double>(losses::physics_input_from_sample(s, seq.info, settings));
    const int64_t N = s.num_vertices();
    std::vector<double> x(3 * N);  // Blender's x_{t+1} in the energy's frame (t+1's root)
    for (int64_t v = 0; v < N; ++v)
      for (int c = 0; c < 3; ++c) x[3 * v + c] = s.target(v, c);
    auto gradient = [&](auto term) {
      ad::Tape<double> tape;
      const ad::Var<double> X = tape.leaf(x.data(), N, 3);
      tape.backward(term(tape, X));
      Eigen::VectorXd g(3 * N);
      for (int64_t k = 0; k < 3 * N; ++k) g[k] = in.inertia_weight[k / 3] > 0 ? X.grad[k] : 0.0;  // pinned rows follow the body
      return g;
    };
    const Eigen::VectorXd inertia = gradient([&](auto& tape, const auto& X) { return losses::inertia_energy(tape, X, in); });
    std::array<Eigen::VectorXd, kTerms> g;
    g[0] = gradient([&](auto& tape, const auto& X) { return losses::drag_energy(tape, X, in); });
    g[1] = gradient([&](auto& tape, const auto& X) { return losses::stretch_energy(tape, X, in); });
    g[2] = gradient([&](auto& tape, const auto& X) { return losses::bending_energy(tape, X, in); });
    g[3] = gradient([&](auto& tape, const auto& X) { return losses::work_energy(tape, X, in, in.external_force); });
    g[4] = gradient([&](auto& tape, const auto& X) { return losses::work_energy(tape, X, in, in.wind_force); });
    g[5] = gradient([&](auto& tape, const auto& X) {
      return losses::body_collision_energy(tape, X, in, settings.body_margin, settings.collision_stiffness);
    });
    g[6] = in.garment_offsets.size() >= 3 ? gradient([&](auto& tape, const auto& X) {
      return losses::layer_collision_energy(tape, X, in, settings.layer_margin, settings.collision_stiffness);
    })
                                          : Eigen::VectorXd::Zero(3 * N);
    for (int64_t v = 0; v < N; ++v) {
      if (in.inertia_weight[v] == 0) continue;
      for (int i = 0; i <= kTerms; ++i)
        vertex_norm[i].push_back(static_cast<float>((i < kTerms ? g[i] : inertia).segment<3>(3 * v).norm()));
    }
    for (int i = 0; i < kTerms; ++i) {
      cross[i] -= g[i].dot(inertia);
      for (int j = 0; j < kTerms; ++j) gram(i, j) += g[i].dot(g[j]);
    }
    inertia_sq += inertia.squaredNorm();
    ++frames;
  }
  // ‖g_inertia + Σ w_k g_k‖² relative to ‖g_inertia‖².
  double residual(const Eigen::Matrix<double, kTerms, 1>& w) const {
    return (inertia_sq - 2 * w.dot(cross) + w.dot(gram * w)) / inertia_sq;
  }
  void print(int sequences) const {
    std::printf("Blender's next frame in the physics energy (val split, %d sequences, %d frames; a frame the energy "
                "describes has gradient 0):\n  term              gradient / inertia's: rms   per-vertex median   p90\n",
                sequences, frames);
    auto quantile = [](std::vector<float> v, double q) {
      if (v.empty()) return 0.0;
      const auto k = static_cast<std::ptrdiff_t>(q * static_cast<double>(v.size() - 1));
      std::nth_element(v.begin(), v.begin() + k, v.end());
      return static_cast<double>(v[k]);
    };
    const double inertia_median = quantile(vertex_norm[kTerms], 0.5), inertia_p90 = quantile(vertex_norm[kTerms], 0.9);
    for (int k = 0; k < kTerms; ++k)
      std::printf("  %-17s %10.3g %14.3g %12.3g\n", kNames[k], std::sqrt(gram(k, k) / inertia_sq),
                  quantile(vertex_norm[k], 0.5) / inertia_median, quantile(vertex_norm[k], 0.9) / inertia_p90);
    const Eigen::Matrix<double, kTerms, 1> ones = Eigen::Matrix<double, kTerms, 1>::Ones();
    std::printf("  |gradient|^2 / |inertia's|^2 with Blender's weights (all 1): %.4g\n", residual(ones));
    // Terms absent from every frame (no wind, one layer) stay at weight 0.
    Eigen::Matrix<double, kTerms, kTerms> a = gram;
    for (int k = 0; k < kTerms; ++k)
      if (a(k, k) == 0) a(k, k) = 1;
    const Eigen::Matrix<double, kTerms, 1> fit = a.ldlt().solve(cross);
    std::printf("  least-squares weights (inertia 1):");
    for (int k = 0; k < kTerms; ++k) std::printf(" %s %.3g%s", kNames[k], fit[k], k + 1 < kTerms ? "," : "");
    std::printf("\n  |gradient|^2 / |inertia's|^2 with them: %.4g (1 = the terms explain none of Blender's acceleration)\n",
                residual(fit));
  }
};

// Per-frame motion statistics of one split (every frame after each sequence's ramp).
struct MotionTally {
  static constexpr float kWindy = 50.f, kStrong = 250.f;  // the generator's calm / windy bounds
  std::vector<float> body_speed, turn_rate;                // per frame
  std::vector<float> cloth_speed_calm, cloth_speed_wind;   // per frame, mean over free vertices, m/s
  int64_t frames = 0, windy = 0, strong = 0;
  int sequences = 0;
  void add_sequence(const SequenceFile& f) {
    const SequenceInfo& info = f.info();
    const int first = std::min(info.settled_frame(), info.num_frames - 2);
    const FrameWindow w = f.read_frames(first, info.num_frames - first);
    ++sequences;
    const double to_m_per_s = info.fps / info.scale;
    for (int t = first + 1; t < info.num_frames; ++t) {
      const Points body_before = w.body_at(t - 1, info.num_body_vertices), body = w.body_at(t, info.num_body_vertices);
      const BodyStep step = body_step(body_before, body, info.up_axis, info.fps, info.scale);
      body_speed.push_back(static_cast<float>(step.speed));
      turn_rate.push_back(static_cast<float>(step.turn_rate));
      double sum = 0;
      int64_t count = 0;
      for (int k = 0; k < info.num_garments(); ++k) {
        const GarmentMesh& g = info.garments[k];
        const Points a = w.garment_at(k, t - 1, g.num_vertices), b = w.garment_at(k, t, g.num_vertices);
        for (int v = 0; v < g.num_vertices; ++v)
          if (!g.pinned(v)) sum += (b.row(v) - a.row(v) - step.shift).norm(), ++count;
      }
      const float strength = info.has_wind ? info.wind_strength[t] : 0.f;
      ++frames, windy += strength > kWindy, strong += strength > kStrong;
      if (count > 0)
        (strength > kWindy ? cloth_speed_wind : cloth_speed_calm)
            .push_back(static_cast<float>(sum / static_cast<double>(count) * to_m_per_s));
    }
  }
  static std::string summary(std::vector<float> v) {
    if (v.empty()) return "none";
    std::sort(v.begin(), v.end());
    const std::vector<double> d(v.begin(), v.end());
    double sum = 0;
    for (double x : d) sum += x;
    char buf[160];
    std::snprintf(buf, sizeof buf, "mean %.3g, p50 %.3g, p90 %.3g, p99 %.3g, max %.3g", sum / static_cast<double>(d.size()),
                  quantile(d, 0.5), quantile(d, 0.9), quantile(d, 0.99), d.back());
    return buf;
  }
  void print(const char* split) const {
    if (frames == 0) {
      std::printf("  %-5s no frames after the ramp\n", split);
      return;
    }
    const auto share = [&](int64_t n) { return 100.0 * static_cast<double>(n) / static_cast<double>(frames); };
    int64_t fast_turns = 0;
    for (float r : turn_rate) fast_turns += r > 0.5f;
    std::printf("  %-5s %d sequences, %ld frames\n", split, sequences, static_cast<long>(frames));
    std::printf("        body speed, m/s: %s\n", summary(body_speed).c_str());
    std::printf("        turn rate, turns/s: %s; %.1f%% of frames above 0.5\n", summary(turn_rate).c_str(), share(fast_turns));
    std::printf("        wind above %g: %.1f%% of frames, above %g: %.1f%%\n", kWindy, share(windy), kStrong, share(strong));
    std::printf("        garment speed against the body's centroid (mean over unpinned vertices), m/s: calm frames %s\n",
                summary(cloth_speed_calm).c_str());
    std::printf("          frames with wind above %g: %s\n", kWindy, summary(cloth_speed_wind).c_str());
  }
};

}  // namespace

BodyStep body_step(const Points& before, const Points& after, char up_axis, float fps, float scale) {
  LAYERSNET_CHECK(before.rows() == after.rows() && before.rows() > 0, "body_step: frames of different vertex counts");
  const Eigen::RowVector3f c0 = before.colwise().mean(), c1 = after.colwise().mean();
  BodyStep s;
  s.shift = c1 - c0;
  s.speed = static_cast<double>(s.shift.norm()) * fps / scale;
  // Horizontal axes: the two that are not up (z up: x, y; y up: z, x, keeping a right-handed yaw).
  const int a = up_axis == 'z' ? 0 : 2, b = up_axis == 'z' ? 1 : 0;
  double cross = 0, dot = 0;
  for (Eigen::Index i = 0; i < before.rows(); ++i) {
    const double pa = before(i, a) - c0[a], pb = before(i, b) - c0[b];
    const double qa = after(i, a) - c1[a], qb = after(i, b) - c1[b];
    cross += pa * qb - pb * qa, dot += pa * qa + pb * qb;
  }
  s.turn_rate = std::fabs(std::atan2(cross, dot)) / (2 * M_PI) * fps;
  return s;
}

void inspect_dataset(const InspectOptions& o, const SampleOptions& sample_options) {
  const float patch_size = sample_options.patch_size;
  const DatasetManifest m = read_manifest(o.root);
  std::printf("data set %s: %zu sequences (train %zu, val %zu, test %zu)\nsource: %s\n", o.root.c_str(),
              m.all_ids().size(), m.train.size(), m.val.size(), m.test.size(), m.source.c_str());
  if (std::filesystem::exists(m.stats_path())) {
    const NormalisationStats s = read_stats(m.stats_path());
    std::printf("stats.h5: from %zu training sequences; position std (%.4g, %.4g, %.4g), velocity std (%.4g, %.4g, %.4g)\n",
                s.sequences.size(), s.position.std[0], s.position.std[1], s.position.std[2], s.velocity.std[0],
                s.velocity.std[1], s.velocity.std[2]);
  } else {
    std::printf("stats.h5: missing (create it with `layersnet prepare %s`)\n", o.root.c_str());
  }
  int64_t frames = 0, garments = 0, vertices = 0, patches = 0, with_wind = 0;
  std::set<std::string> types;
  CrossGarmentTally cross_total;
  for (const char* split : {"train", "val", "test"}) {
    for (const auto& id : m.split(split)) {
      const SequenceFile f(m.sequence_path(id));
      if (o.check) (void)f.read_all();
      const SequenceInfo& info = f.info();
      frames += info.num_frames;
      with_wind += info.has_wind;
      if (!o.brief)
        std::printf("%-12s %-5s %4d frames @ %g fps, body %d vertices / %ld faces, friction %.3g, %d garment(s)%s\n",
                    id.c_str(), split, info.num_frames, info.fps, info.num_body_vertices,
                    static_cast<long>(info.body_faces.rows()), info.body_friction, info.num_garments(),
                    o.check ? ", all values checked" : "");
      for (const auto& g : info.garments) {
        const PatchStructure p = build_patches(g, patch_size);
        ++garments;
        vertices += g.num_vertices;
        patches += p.num_patches;
        types.insert(g.type);
        if (!o.brief)
          std::printf("    garment %-16s type %-22s N %6d  F %6d  panels %3d  patches %5d  pinned %4d  (tension %.3g, "
                      "bending %.3g, mass %.3g, self-friction %.3g)\n",
                      g.name.c_str(), g.type.c_str(), g.num_vertices, g.num_faces(),
                      static_cast<int>(std::set<int32_t>(g.panel.begin(), g.panel.end()).size()), p.num_patches,
                      g.num_pinned(),
                      g.attributes.tension_stiffness, g.attributes.bending_stiffness, g.attributes.mass,
                      g.attributes.self_friction);
      }
      if (!o.brief) print_wind(info);
      int t = 0;
      const std::vector<int32_t> cross = cross_garment_edges(f, sample_options, &t);
      cross_total.add(cross);
      if (!o.brief && info.num_garments() >= 2) {
        CrossGarmentTally one;
        one.add(cross);
        std::printf("    at frame %d:", t);
        one.print(" ");
      }
    }
  }
  std::printf("total: %ld frames, %ld garments (%zu types), %ld garment vertices, %ld patches (size %g), %ld/%zu "
              "sequences with wind\n",
              static_cast<long>(frames), static_cast<long>(garments), types.size(), static_cast<long>(vertices),
              static_cast<long>(patches), patch_size, static_cast<long>(with_wind), m.all_ids().size());
  std::printf("cross-garment world edges (world radius %g, at the first frame after each ramp, else 2):", sample_options.neighbours.world_radius);
  cross_total.print(" ");
  if (o.margins) {
    MarginTally tally;
    for (const auto& id : m.train) {
      const SequenceFile f(m.sequence_path(id));
      const SequenceInfo& info = f.info();
      const int first = std::min(info.settled_frame(), info.num_frames - 1);
      const FrameWindow w = f.read_frames(first, info.num_frames - first);
      const GarmentLayout layout = garment_layout(info);
      const Faces inner = inner_faces(layout);
      for (int t = first; t < info.num_frames; ++t) tally.add_frame(info, layout, inner, w, t);
    }
    std::printf("ground-truth collision distances, scene units (the collision loss penalises d < loss.collision_eps):\n");
    MarginTally::print("garment to nearest body vertex", tally.body);
    MarginTally::print("outer garment to nearest inner vertex", tally.layer);
    MarginTally::print_ratios("edge strain (length / rest length - 1; eval.strain_limit bounds its magnitude)", tally.stretch);
    MarginTally::print_ratios("far-corner distance of triangles sharing an edge / rest - 1 (eval.fold_limit bounds "
                              "its shortening)", tally.fold);
    tally.print_slip();
  }
  if (o.motion) {
    std::printf("motion after the ramp (what the data can teach about dynamics):\n");
    for (const char* split : {"train", "val", "test"}) {
      MotionTally tally;
      for (const auto& id : m.split(split)) tally.add_sequence(SequenceFile(m.sequence_path(id)));
      tally.print(split);
    }
  }
  if (o.physics) {
    PhysicsBalance balance;
    int sequences = 0;
    for (const auto& id : m.split("val")) {
      const Sequence seq = read_sequence(m.sequence_path(id));
      const auto structure = build_structure(seq.info, patch_size);
      for (int t = std::max(2, seq.info.settled_frame()); t <= seq.info.num_frames - 2; t += 10) balance.add(seq, structure, t);
      ++sequences;
    }
    if (balance.frames == 0)
      std::printf("physics: the val split has no frame after the ramp\n");
    else
      balance.print(sequences);
  }
  if (o.pins) {
    using ErrorsOf = std::vector<float> (*)(const Sequence&, int);
    const std::pair<const char*, ErrorsOf> ways[] = {
        {"carried with the body from frame to frame (eval.pins)", carried_pin_errors},
        {"rigged from the body (simulate, eval --rig-pins)", rigged_pin_errors}};
    constexpr size_t W = std::size(ways);
    const char* const splits[] = {"train", "val", "test"};
    // Each sequence is read once for both ways; their reports are printed one after the other.
    std::string report[W];
    const auto add = [&report](size_t w, const char* format, auto... values) {
      char line[160];
      std::snprintf(line, sizeof line, format, values...);
      report[w] += line;
    };
    for (const char* split : splits) {
      std::vector<float> all[W];
      int sequences[W] = {};
      for (const auto& id : m.split(split)) {
        const Sequence seq = read_sequence(m.sequence_path(id));
        const int first = std::max(2, std::min(seq.info.settled_frame(), seq.info.num_frames - 2));
        const double mm = 1000.0 / seq.info.scale;
        for (size_t w = 0; w < W; ++w) {
          const std::vector<float> e = ways[w].second(seq, first);
          if (e.empty()) continue;
          ++sequences[w];
          for (float d : e) all[w].push_back(static_cast<float>(d * mm));
          if (!o.brief) {
            double sum = 0;
            for (float d : e) sum += d;
            add(w, "    %-12s %-5s mean %.1f  max %.1f\n", id.c_str(), split, sum / static_cast<double>(e.size()) * mm,
                *std::max_element(e.begin(), e.end()) * mm);
          }
        }
      }
      for (size_t w = 0; w < W; ++w) {
        if (all[w].empty()) {
          add(w, "  %-5s no pinned vertices\n", split);
          continue;
        }
        double sum = 0;
        for (float d : all[w]) sum += d;
        std::sort(all[w].begin(), all[w].end());
        const std::vector<float>& a = all[w];
        add(w, "  %-5s %d sequences: mean %.1f, p50 %.1f, p99 %.1f, max %.1f\n", split, sequences[w],
            sum / static_cast<double>(a.size()), a[a.size() / 2], a[a.size() * 99 / 100], a.back());
      }
    }
    for (size_t w = 0; w < W; ++w)
      std::printf("pinned vertices %s, from the first frame after the ramp to the last, distance from the ground "
                  "truth's, mm:\n%s", ways[w].first, report[w].c_str());
  }
}


}  // namespace layersnet::eval
