// Stress scenes, distance bounds and the float32/float64 comparison (see stress.h).
#include "eval/stress.h"

#include "dataset/sequence.h"
#include "dataset/neighbours.h"
#include "dataset/wind.h"
#include "eval/evaluate.h"
#include "eval/machine.h"
#include "eval/metrics.h"
#include "model/layersnet.h"
#include "model/params_layout.h"
#include "model/sample_input.h"

#include <algorithm>
#include <cmath>
#include <functional>
#include <limits>
#include <queue>
#include <stdexcept>

namespace layersnet::eval {

namespace {

// Source time of stress frame t: forward over [0, T−1], then backward, ...
double pingpong(double x, int T) {
  const double period = 2.0 * (T - 1);
  const double m = std::fmod(x, period);
  return m <= T - 1 ? m : period - m;
}

// Rows of frame u (fractional) of a (T·n, 3) block, linearly interpolated.
Points interpolate(const Points& block, int n, int T, double u) {
  const int f0 = std::min(static_cast<int>(std::floor(u)), T - 1), f1 = std::min(f0 + 1, T - 1);
  const float w = static_cast<float>(u - f0);
  const auto a = block.middleRows(static_cast<Eigen::Index>(f0) * n, n);
  const auto b = block.middleRows(static_cast<Eigen::Index>(f1) * n, n);
  return (1.f - w) * a + w * b;
}

// Rotation (w, x, y, z) that maps +z (the wind axis of the spec) to +x: 90° about y.
Eigen::Vector4f plus_x_wind() {
  const float h = static_cast<float>(std::sqrt(0.5));
  return {h, 0.f, h, 0.f};
}

}  // namespace

dataset::Sequence make_stress_sequence(const dataset::Sequence& source, const StressScene& scene) {
  const dataset::SequenceInfo& in = source.info;
  const int T = in.num_frames, F = scene.frames, B = in.num_body_vertices;
  const int f0 = scene.first;
  if (F < 4 || !(scene.speed > 0) || f0 < 0 || f0 > T - 2)
    throw std::invalid_argument(in.path + ": a stress scene needs frames >= 4 (got " + std::to_string(F) +
                                "), speed > 0 (got " + std::to_string(scene.speed) + ") and a first frame in [0, T-2] (got " +
                                std::to_string(f0) + ", T = " + std::to_string(T) + ")");
  dataset::Sequence out;
  out.info = in;
  out.info.path = in.path + " (stress)";
  out.info.num_frames = F;
  out.info.has_translation = true;
  out.info.translation.resize(F, 3);
  out.frames.first = 0;
  out.frames.count = F;
  out.frames.body.resize(static_cast<Eigen::Index>(F) * B, 3);
  out.frames.garments.assign(in.num_garments(), Points());
  for (int g = 0; g < in.num_garments(); ++g)
    out.frames.garments[g].resize(static_cast<Eigen::Index>(F) * in.garments[g].num_vertices, 3);
  // The source's translation as a (T, 3) block (zeros when the file has none).
  Points translation = in.translation.rows() == T ? in.translation : Points::Zero(T, 3);

  // Wind: constant strength along the first windy segment's rotation, or the source's.
  const auto segments = dataset::wind_segments(in);
  Eigen::Vector4f wind_q = plus_x_wind();
  for (const auto& s : segments)
    if (s.strength > 0) {
      wind_q = s.rotation;
      break;
    }
  const bool constant_wind = scene.wind_strength >= 0;
  out.info.has_wind = constant_wind || in.has_wind;
  if (out.info.has_wind) {
    out.info.wind_rotation.resize(F, 4);
    out.info.wind_strength.resize(F);
  }
  for (int t = 0; t < F; ++t) {
    const double u = f0 + pingpong(scene.speed * t, T - f0);
    out.frames.body.middleRows(static_cast<Eigen::Index>(t) * B, B) = interpolate(source.frames.body, B, T, u);
    out.info.translation.row(t) = interpolate(translation, 1, T, u);
    for (int g = 0; g < in.num_garments(); ++g) {
      const int n = in.garments[g].num_vertices;
      out.frames.garments[g].middleRows(static_cast<Eigen::Index>(t) * n, n) =
          interpolate(source.frames.garments[g], n, T, u);
    }
    if (constant_wind) {
      out.info.wind_rotation.row(t) = wind_q.transpose();
      out.info.wind_strength[t] = static_cast<float>(scene.wind_strength);
    } else if (in.has_wind) {
      const int f = std::min(static_cast<int>(std::lround(u)), T - 1);  // piecewise constant in the data
      out.info.wind_rotation.row(t) = in.wind_rotation.row(f);
      out.info.wind_strength[t] = in.wind_strength[f];
    }
  }
  return out;
}

double body_top_speed(const dataset::Sequence& source, int first, double speed, int frames) {
  const int T = source.info.num_frames, B = source.info.num_body_vertices;
  Points prev = interpolate(source.frames.body, B, T, first);
  double top = 0;
  for (int t = 1; t < frames; ++t) {
    Points x = interpolate(source.frames.body, B, T, first + pingpong(speed * t, T - first));
    top = std::max(top, (x - prev).rowwise().norm().maxCoeff() * 1.0);
    prev = std::move(x);
  }
  return top;
}

double speed_factor_for_top_speed(const dataset::Sequence& source, int first, double multiple, int frames) {
  // Not monotone in s (strides alias with the ping-pong), so a scan: the smallest s on a
  // grid of step 0.05·multiple that reaches the target, else the grid's fastest.
  const double target = multiple * body_top_speed(source, first, 1.0, frames);
  double best_s = multiple, best = -1;
  for (int k = 0; k <= 60; ++k) {
    const double s = multiple * (1 + 0.05 * k);
    const double top = body_top_speed(source, first, s, frames);
    if (top >= target) return s;
    if (top > best) best = top, best_s = s;
  }
  return best_s;
}

int settled_frame(const std::string& sequence_path, int missing) {
  const int settled = dataset::SequenceFile(sequence_path).info().settled_frame();
  return settled > 0 ? settled : missing;
}

std::vector<double> garment_graph_diameters(const dataset::Sequence& seq) {
  return garment_graph_diameters(seq, garment_edges(seq));
}

std::vector<double> garment_graph_diameters(const dataset::Sequence& seq, const GarmentEdges& edges) {
  std::vector<double> out;
  size_t e = 0;
  Eigen::Index offset = 0;
  for (int g = 0; g < seq.info.num_garments(); ++g) {
    const int n = seq.info.garments[g].num_vertices;
    // Undirected adjacency with rest lengths, local vertex indices.
    std::vector<std::vector<std::pair<int, double>>> adj(static_cast<size_t>(n));
    for (; e < edges.rows.size() && edges.rows[e].first < offset + n; ++e) {
      const int a = static_cast<int>(edges.rows[e].first - offset), b = static_cast<int>(edges.rows[e].second - offset);
      adj[static_cast<size_t>(a)].push_back({b, edges.rest[e]});
      adj[static_cast<size_t>(b)].push_back({a, edges.rest[e]});
    }
    offset += n;
    double diameter = 0;
    std::vector<double> dist(static_cast<size_t>(n));
    using Item = std::pair<double, int>;
    for (int s = 0; s < n; ++s) {
      std::fill(dist.begin(), dist.end(), std::numeric_limits<double>::infinity());
      std::priority_queue<Item, std::vector<Item>, std::greater<Item>> queue;
      dist[static_cast<size_t>(s)] = 0;
      queue.push({0.0, s});
      while (!queue.empty()) {
        const auto [d, v] = queue.top();
        queue.pop();
        if (d > dist[static_cast<size_t>(v)]) continue;
        for (const auto& [w, len] : adj[static_cast<size_t>(v)])
          if (d + len < dist[static_cast<size_t>(w)]) {
            dist[static_cast<size_t>(w)] = d + len;
            queue.push({d + len, w});
          }
      }
      // A garment in several pieces: the farthest reachable vertex (each piece is bounded
      // by its own diameter; an unreachable vertex is not a path).
      for (double d : dist)
        if (std::isfinite(d)) diameter = std::max(diameter, d);
    }
    out.push_back(diameter);
  }
  return out;
}

std::vector<GarmentBodyDistance> garment_body_distances(const dataset::Sequence& seq, int t, const Points& x) {
  std::vector<GarmentBodyDistance> out;
  const Points body = seq.body_at(t);
  Eigen::Index row = 0;
  for (int g = 0; g < seq.info.num_garments(); ++g) {
    const int n = seq.info.garments[g].num_vertices;
    const auto part = x.middleRows(row, n);
    row += n;
    if (!part.allFinite()) {
      const double nan = std::numeric_limits<double>::quiet_NaN();
      out.push_back({nan, nan});
      continue;
    }
    const dataset::NearestBody nn = dataset::nearest_body(part, body);
    GarmentBodyDistance d;
    if (!nn.distance.empty()) {
      const auto [lo, hi] = std::minmax_element(nn.distance.begin(), nn.distance.end());
      d = {static_cast<double>(*hi), static_cast<double>(*lo)};
    }
    out.push_back(d);
  }
  return out;
}

GarmentEdges garment_edges(const dataset::Sequence& seq) { return dataset::garment_edges(seq.info, rest_garments(seq)); }

double max_edge_stretch(const GarmentEdges& edges, const Points& x) {
  double worst = 0;
  for (size_t e = 0; e < edges.rows.size(); ++e)
    if (edges.rest[e] > 0) {
      const auto [a, b] = edges.rows[e];
      worst = std::max(worst, (x.row(a) - x.row(b)).cast<double>().norm() / edges.rest[e]);
    }
  return worst;
}

StrainExtremes frame_strain(const GarmentEdges& edges, const Points& x) {
  std::vector<double> e = edge_strains(edges, x);
  if (e.empty()) return {};
  const double top = *std::max_element(e.begin(), e.end());
  return {quantile(std::move(e), 0.99), top};
}

StrainExtremes data_strain(const dataset::Sequence& seq, int first) {
  const GarmentEdges edges = garment_edges(seq);
  StrainExtremes worst;
  for (int t = std::max(first, 0); t < seq.info.num_frames; ++t) {
    const StrainExtremes s = frame_strain(edges, garments_at(seq, t));
    worst = {std::max(worst.p99, s.p99), std::max(worst.max, s.max)};
  }
  return worst;
}

StrainExtremes data_set_strain(const dataset::DatasetManifest& manifest) {
  StrainExtremes worst;
  for (const std::string& id : manifest.all_ids()) {
    const std::string path = manifest.sequence_path(id);
    const dataset::Sequence seq = dataset::read_sequence(path);
    const StrainExtremes s = data_strain(seq, seq.info.settled_frame());
    worst = {std::max(worst.p99, s.p99), std::max(worst.max, s.max)};
  }
  return worst;
}

std::vector<double> garment_distance_bounds(const dataset::Sequence& seq) {
  return garment_distance_bounds(seq, garment_graph_diameters(seq));
}

std::vector<double> garment_distance_bounds(const dataset::Sequence& seq, const std::vector<double>& diameters) {
  std::vector<double> out;
  const Points body = seq.body_at(0);
  for (int g = 0; g < seq.info.num_garments(); ++g) {
    const dataset::NearestBody nn = dataset::nearest_body(seq.garment_at(g, 0), body);
    const double gap = nn.distance.empty() ? 0.0 : *std::min_element(nn.distance.begin(), nn.distance.end());
    out.push_back(gap + kStretchAllowance * diameters[static_cast<size_t>(g)]);
  }
  return out;
}

double data_bound_ratio(const dataset::Sequence& source, int first) {
  StressScene scene;
  scene.frames = 4;
  scene.first = first;
  const std::vector<double> bounds = garment_distance_bounds(make_stress_sequence(source, scene));
  double worst = 0;
  for (int t = first; t < source.info.num_frames; ++t) {
    const std::vector<GarmentBodyDistance> d = garment_body_distances(source, t, garments_at(source, t));
    for (size_t g = 0; g < d.size(); ++g) worst = std::max(worst, d[g].farthest / bounds[g]);
  }
  return worst;
}

StressResult stress_rollout(Predictor& predictor, const dataset::Sequence& source, const StressScene& scene,
                            const std::string& label, double strain_limit) {
  const dataset::Sequence seq = make_stress_sequence(source, scene);
  StressResult res;
  res.label = label;
  res.scene = scene;
  res.strain_limit = strain_limit;
  const GarmentEdges edges = garment_edges(seq);
  const std::vector<double> diameters = garment_graph_diameters(seq, edges);
  res.bounds = garment_distance_bounds(seq, diameters);
  for (int t = 1; t < seq.info.num_frames; ++t) {
    const auto v = seq.body_at(t) - seq.body_at(t - 1);
    res.max_body_speed = std::max(res.max_body_speed, static_cast<double>(v.rowwise().norm().maxCoeff()));
  }
  const Rollout r = rollout(predictor, seq, 2, seq.info.num_frames - 3);
  res.frames = static_cast<int>(r.frames.size());
  res.finite = r.diverged_at < 0;
  Points prev = garments_at(seq, 2);
  for (int k = 0; k < res.frames; ++k) {
    const Points& x = r.frames[static_cast<size_t>(k)];
    if (!x.allFinite()) {
      if (res.first_bad_frame < 0) res.first_bad_frame = k;
      break;
    }
    // In double: a blown-up rollout near the float range would overflow the difference.
    const double speed = (x.cast<double>() - prev.cast<double>()).rowwise().norm().maxCoeff();
    res.max_vertex_speed = std::max(res.max_vertex_speed, speed);
    res.vertex_speed_per_frame.push_back(speed);
    prev = x;
    const std::vector<GarmentBodyDistance> d = garment_body_distances(seq, r.first_frame + k, x);
    res.bound_ratio_per_frame.push_back(0.0);
    res.nearest_per_frame.push_back(0.0);
    res.edge_stretch_per_frame.push_back(max_edge_stretch(edges, x));
    const StrainExtremes strain = frame_strain(edges, x);
    res.strain_p99_per_frame.push_back(strain.p99);
    res.strain_max_per_frame.push_back(strain.max);
    res.max_strain_p99 = std::max(res.max_strain_p99, strain.p99);
    res.max_strain = std::max(res.max_strain, strain.max);
    const bool torn = strain.p99 > strain_limit;
    if (torn && res.first_torn_frame < 0) res.first_torn_frame = k;
    if (torn && res.first_bad_frame < 0) res.first_bad_frame = k;
    for (size_t g = 0; g < d.size(); ++g) {
      res.nearest_per_frame.back() = std::max(res.nearest_per_frame.back(), d[g].nearest);
      const double ratio = d[g].farthest / res.bounds[g];
      res.max_bound_ratio = std::max(res.max_bound_ratio, ratio);
      res.bound_ratio_per_frame.back() = std::max(res.bound_ratio_per_frame.back(), ratio);
      if (diameters[g] > 0) res.max_diameter_ratio = std::max(res.max_diameter_ratio, d[g].farthest / diameters[g]);
      if (ratio > 1 && res.first_bad_frame < 0) res.first_bad_frame = k;
    }
  }
  std::vector<double> ms;
  for (double m : r.step_ms)
    if (m > 0) ms.push_back(m);
  res.ms_per_frame = median(ms);
  return res;
}

namespace {

// The float32 parameters converted to double, in the layout of `model` (throws on a mismatch).
ad::ParamStore<double> to_double(const ModelConfig& model, const ad::ParamStore<float>& params) {
  ad::ParamStore<double> out;
  model::register_params(out, model);
  if (out.total_size() != params.total_size())
    throw std::invalid_argument("float64 model: the float32 parameters hold " + std::to_string(params.total_size()) +
                                " values, the config's layout " + std::to_string(out.total_size()) +
                                "; pass the parameters loaded with the same config");
  std::copy(params.values().begin(), params.values().end(), out.values().begin());
  return out;
}

}  // namespace

DoubleModelPredictor::DoubleModelPredictor(Config config, const ad::ParamStore<float>& params,
                                           dataset::NormalisationStats stats)
    : NetworkPredictor<double>(config, to_double(config.model, params), std::move(stats)) {}

double PrecisionResult::worst_mean() const {
  double m = 0;
  for (double d : mean_divergence) m = std::isfinite(d) ? std::max(m, d) : std::numeric_limits<double>::infinity();
  return m;
}
double PrecisionResult::worst_max() const {
  double m = 0;
  for (double d : max_divergence) m = std::isfinite(d) ? std::max(m, d) : std::numeric_limits<double>::infinity();
  return m;
}

PrecisionResult compare_precision(const Config& config, const ad::ParamStore<float>& params,
                                  const dataset::NormalisationStats& stats, const dataset::Sequence& source,
                                  int frames, int first) {
  ModelPredictor single("float32", config, params, stats);
  DoubleModelPredictor dbl(config, params, stats);
  PrecisionResult res;
  res.mm_per_unit = 1000.0 / source.info.scale;
  // The model's own error level on the source (every frame it has).
  const Rollout own = rollout(single, source, 2, source.info.num_frames - 3);
  res.model_error = own.diverged_at < 0 ? score_rollout(source, own, {}).error : std::numeric_limits<double>::infinity();

  StressScene scene;
  scene.frames = frames + 3;
  scene.first = first;
  const dataset::Sequence seq = make_stress_sequence(source, scene);
  const Rollout a = rollout(single, seq, 2, frames), b = rollout(dbl, seq, 2, frames);
  res.frames = static_cast<int>(a.frames.size());
  res.finite = a.diverged_at < 0 && b.diverged_at < 0;
  for (int k = 0; k < res.frames; ++k) {
    const Eigen::VectorXf d = (a.frames[static_cast<size_t>(k)] - b.frames[static_cast<size_t>(k)]).rowwise().norm();
    const bool ok = d.allFinite();
    res.max_divergence.push_back(ok ? d.maxCoeff() : std::numeric_limits<double>::quiet_NaN());
    res.mean_divergence.push_back(ok ? d.cast<double>().mean() : std::numeric_limits<double>::quiet_NaN());
  }
  std::vector<double> ms_a, ms_b;
  for (double m : a.step_ms) if (m > 0) ms_a.push_back(m);
  for (double m : b.step_ms) if (m > 0) ms_b.push_back(m);
  res.ms_float = median(ms_a);
  res.ms_double = median(ms_b);
  return res;
}

}  // namespace layersnet::eval
