// Per-frame metrics (definitions in metrics.h).
#include "eval/metrics.h"

#include "dataset/neighbours.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <set>
#include <stdexcept>

namespace layersnet::eval {

namespace {
// Rows of x that are finite (nearest-neighbour queries with NaN are undefined).
std::vector<Eigen::Index> finite_rows(const Eigen::Ref<const Points>& x) {
  std::vector<Eigen::Index> rows;
  for (Eigen::Index v = 0; v < x.rows(); ++v)
    if (x.row(v).allFinite()) rows.push_back(v);
  return rows;
}
Points take_rows(const Eigen::Ref<const Points>& x, const std::vector<Eigen::Index>& rows) {
  Points out(static_cast<Eigen::Index>(rows.size()), 3);
  for (size_t i = 0; i < rows.size(); ++i) out.row(static_cast<Eigen::Index>(i)) = x.row(rows[i]);
  return out;
}
}  // namespace

double mean_vertex_error(const Eigen::Ref<const Points>& pred, const Eigen::Ref<const Points>& truth) {
  if (pred.rows() != truth.rows() || pred.rows() == 0)
    throw std::invalid_argument("mean_vertex_error: prediction has " + std::to_string(pred.rows()) +
                                " rows, ground truth " + std::to_string(truth.rows()) + " (need the same, > 0)");
  double sum = 0;
  for (Eigen::Index v = 0; v < pred.rows(); ++v)
    sum += (pred.row(v).cast<double>() - truth.row(v).cast<double>()).norm();
  return sum / static_cast<double>(pred.rows());
}

int64_t count_body_collisions(const Eigen::Ref<const Points>& garments, const Eigen::Ref<const Points>& body,
                              const Faces& body_faces, double max_distance) {
  const Points q = take_rows(garments, finite_rows(garments));
  if (q.rows() == 0 || body.rows() == 0) return 0;
  const Points normals = dataset::vertex_normals(body, body_faces);
  const dataset::NearestBody nearest = dataset::nearest_body(q, body);
  int64_t count = 0;
  for (Eigen::Index v = 0; v < q.rows(); ++v) {
    const int32_t h = nearest.index[v];
    const Eigen::Vector3d d = (q.row(v) - body.row(h)).cast<double>().transpose();
    if (max_distance >= 0 && d.norm() > max_distance) continue;
    if (d.dot(normals.row(h).cast<double>().transpose()) < 0) ++count;
  }
  return count;
}

int64_t count_layer_collisions(const Eigen::Ref<const Points>& outer, const Eigen::Ref<const Points>& inner,
                               const Faces& inner_faces, double max_distance) {
  const Points q = take_rows(outer, finite_rows(outer));
  // Only finite inner vertices can be "nearest"; normals from the full mesh
  // (vertex_normals skips faces with a non-finite corner).
  const std::vector<Eigen::Index> inner_rows = finite_rows(inner);
  const Points targets = take_rows(inner, inner_rows);
  if (q.rows() == 0 || targets.rows() == 0) return 0;
  const Points normals = dataset::vertex_normals(inner, inner_faces);
  const dataset::NearestBody nearest = dataset::nearest_body(q, targets);
  int64_t count = 0;
  for (Eigen::Index v = 0; v < q.rows(); ++v) {
    const Eigen::Index y = inner_rows[nearest.index[v]];
    const Eigen::Vector3d d = (q.row(v) - inner.row(y)).cast<double>().transpose();
    if (max_distance >= 0 && d.norm() > max_distance) continue;
    if (d.dot(normals.row(y).cast<double>().transpose()) < 0) ++count;
  }
  return count;
}

FrameMetrics frame_metrics(const GarmentLayout& L, const Eigen::Ref<const Points>& pred,
                           const Eigen::Ref<const Points>& truth, const Eigen::Ref<const Points>& body,
                           const Faces& body_faces, const CollisionOptions& o) {
  const int N = L.num_vertices();
  if (pred.rows() != N || truth.rows() != N)
    throw std::invalid_argument("frame_metrics: expected " + std::to_string(N) + " garment vertices, got " +
                                std::to_string(pred.rows()) + " predicted and " + std::to_string(truth.rows()) +
                                " ground-truth rows");
  FrameMetrics m;
  m.error = mean_vertex_error(pred, truth);
  for (int g = 0; g < L.num_garments(); ++g) {
    const int n = L.offsets[g + 1] - L.offsets[g];
    m.garment_error.push_back(mean_vertex_error(pred.middleRows(L.offsets[g], n), truth.middleRows(L.offsets[g], n)));
  }
  const int n_inner = L.layered() ? L.offsets[L.num_garments() - 1] : N;
  m.inner_error = mean_vertex_error(pred.topRows(n_inner), truth.topRows(n_inner));
  m.body_collisions = count_body_collisions(pred, body, body_faces, o.max_body_distance);
  m.h_rate = static_cast<double>(m.body_collisions) / N;
  if (L.layered()) {
    const int n_outer = N - n_inner;
    m.outer_error = mean_vertex_error(pred.bottomRows(n_outer), truth.bottomRows(n_outer));
    m.layer_collisions = count_layer_collisions(pred.bottomRows(n_outer), pred.topRows(n_inner), inner_faces(L));
    m.l_rate_outer = static_cast<double>(m.layer_collisions) / n_outer;
    m.l_rate_all = static_cast<double>(m.layer_collisions) / N;
    m.layer_collisions_near =
        count_layer_collisions(pred.bottomRows(n_outer), pred.topRows(n_inner), inner_faces(L), o.max_layer_distance);
    m.l_rate_outer_near = static_cast<double>(m.layer_collisions_near) / n_outer;
  } else {
    m.layer_collisions = -1;
    m.layer_collisions_near = -1;
  }
  return m;
}

FacePairs adjacent_face_pairs(const GarmentLayout& L) {
  FacePairs out;
  for (int g = 0; g < L.num_garments(); ++g) {
    const Faces& f = L.faces[g];
    const int32_t offset = L.offsets[g];
    // Edge (lo, hi) -> first face seen; a second face closes the pair.
    std::map<std::pair<int32_t, int32_t>, Eigen::Index> open;
    std::set<std::pair<int32_t, int32_t>> closed;
    for (Eigen::Index i = 0; i < f.rows(); ++i)
      for (int k = 0; k < 3; ++k) {
        const int32_t a = f(i, k), b = f(i, (k + 1) % 3);
        const std::pair<int32_t, int32_t> e{std::min(a, b), std::max(a, b)};
        if (closed.count(e)) continue;
        const auto it = open.find(e);
        if (it == open.end()) {
          open.emplace(e, i);
          continue;
        }
        const Eigen::Index j = it->second;
        out.first.push_back({f(j, 0) + offset, f(j, 1) + offset, f(j, 2) + offset});
        out.second.push_back({f(i, 0) + offset, f(i, 1) + offset, f(i, 2) + offset});
        open.erase(it);
        closed.insert(e);
      }
  }
  return out;
}

std::vector<double> dihedral_angles_deg(const FacePairs& pairs, const Eigen::Ref<const Points>& x) {
  const auto normal = [&](const std::array<int32_t, 3>& t) {
    const Eigen::Vector3d a = x.row(t[0]).cast<double>().transpose();
    return Eigen::Vector3d((x.row(t[1]).cast<double>().transpose() - a).cross(x.row(t[2]).cast<double>().transpose() - a));
  };
  std::vector<double> angles;
  angles.reserve(pairs.first.size());
  constexpr double kDegrees = 180.0 / 3.14159265358979323846;
  for (size_t e = 0; e < pairs.first.size(); ++e) {
    const Eigen::Vector3d n1 = normal(pairs.first[e]), n2 = normal(pairs.second[e]);
    const double l1 = n1.norm(), l2 = n2.norm();
    if (!(l1 > 0) || !(l2 > 0) || !std::isfinite(l1) || !std::isfinite(l2)) continue;
    // atan2 of |sin| and cos stays accurate near 0 and 180 degrees, where acos does not.
    angles.push_back(kDegrees * std::atan2(n1.cross(n2).norm(), n1.dot(n2)));
  }
  return angles;
}

MeanStd mean_std(const std::vector<double>& values) {
  MeanStd r;
  r.count = static_cast<int64_t>(values.size());
  if (values.empty()) return r;
  for (double v : values) r.mean += v;
  r.mean /= static_cast<double>(values.size());
  double ss = 0;
  for (double v : values) ss += (v - r.mean) * (v - r.mean);
  r.std = std::sqrt(ss / static_cast<double>(values.size()));
  return r;
}

double quantile(std::vector<double> v, double q) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  const double x = q * static_cast<double>(v.size() - 1);
  const std::size_t i = static_cast<std::size_t>(x);
  return i + 1 < v.size() ? v[i] + (x - static_cast<double>(i)) * (v[i + 1] - v[i]) : v.back();
}

}  // namespace layersnet::eval
