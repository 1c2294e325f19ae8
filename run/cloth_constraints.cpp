#include "run/cloth_constraints.h"

#include "dataset/garments.h"
#include "dataset/neighbours.h"
#include "dataset/pin_carry.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <memory>
#include <numeric>

namespace layersnet {
namespace {

// Relative slack under which a constraint counts as met (float round-off of earlier moves).
constexpr float kTolerance = 1e-4f;
// Collision anchors farther than this (metres, × the file's scale) say nothing about the side:
// the far side of a limb, a coat hem beyond the inner garment (the "near" layer metric's limit).
constexpr float kReachMetres = 0.05f;

constexpr float kUnbounded = std::numeric_limits<float>::infinity();

// Moves the free ends of the pair (a, b), equally when both are free, until its length lies in
// [min_length, max_length]; returns whether it moved (not when within kTolerance × rest of the
// range, degenerate, or both ends pinned). pinned: (N,) 1 = the vertex does not move.
bool project_pair(dataset::Points& x, std::pair<int32_t, int32_t> pair, float min_length, float max_length,
                  float rest, const std::vector<uint8_t>& pinned) {
  const auto [a, b] = pair;
  const float free_a = pinned[static_cast<size_t>(a)] ? 0.f : 1.f, free_b = pinned[static_cast<size_t>(b)] ? 0.f : 1.f;
  if (free_a + free_b == 0.f) return false;
  const Eigen::RowVector3f d = x.row(b) - x.row(a);
  const float length = d.norm();
  const float target = std::clamp(length, min_length, max_length);
  if (std::abs(length - target) <= kTolerance * rest || length == 0.f) return false;
  const Eigen::RowVector3f correction = (length - target) / length / (free_a + free_b) * d;
  x.row(a) += free_a * correction;
  x.row(b) -= free_b * correction;
  return true;
}

// Calls f(v, a) for each vertex v in rows [begin, end) of x, not pinned (pinned (N,): 1 =
// fixed), whose nearest anchor a (`index` holds the anchors) lies within reach; returns how
// many calls returned true.
template <class F>
int64_t for_each_anchored(const dataset::Points& x, Eigen::Index begin, Eigen::Index end,
                          const std::vector<uint8_t>& pinned, const dataset::NearestVertexIndex& index, float reach,
                          F&& f) {
  if (end <= begin) return 0;
  const dataset::NearestBody nearest = index.query_within(x.middleRows(begin, end - begin), reach);
  int64_t moved = 0;
  for (Eigen::Index v = begin; v < end; ++v)
    if (!pinned[static_cast<size_t>(v)] && nearest.distance[v - begin] <= reach)
      moved += f(v, Eigen::Index{nearest.index[v - begin]});
  return moved;
}

// Moves each vertex x_v (rows [begin, end)) whose nearest anchor a (within reach) has
// (x_v − a)·n_a < shell onto the shell along n_a; returns how many moved.
int64_t push_out(dataset::Points& x, Eigen::Index begin, Eigen::Index end, const std::vector<uint8_t>& pinned,
                 const dataset::NearestVertexIndex& index,
                 const Eigen::Ref<const dataset::Points>& anchors, const dataset::Points& normals, float shell,
                 float reach) {
  if (anchors.rows() == 0) return 0;
  return for_each_anchored(x, begin, end, pinned, index, reach, [&](Eigen::Index v, Eigen::Index a) {
    const Eigen::RowVector3f n = normals.row(a);
    const float depth = shell - (x.row(v) - anchors.row(a)).dot(n);
    if (depth <= kTolerance * shell) return false;  // a vertex already on the shell stays unmoved
    x.row(v) += depth * n;
    return true;
  });
}

// Each vertex x_v (rows [begin, end)) whose nearest anchor a (within reach) has
// (x_v − a)·n_a < within loses mu of its displacement relative to a's, tangentially to n_a:
// x_v −= mu (r − (r·n) n), r = (x_v − x_v,before) − (a − a_before). Returns how many moved.
int64_t drag_along(dataset::Points& x, const Eigen::Ref<const dataset::Points>& x_before, Eigen::Index begin, Eigen::Index end,
                   const std::vector<uint8_t>& pinned,
                   const dataset::NearestVertexIndex& index, const Eigen::Ref<const dataset::Points>& anchors,
                   const Eigen::Ref<const dataset::Points>& anchors_before, const dataset::Points& normals,
                   float within, float mu, float reach) {
  if (anchors.rows() == 0) return 0;
  return for_each_anchored(x, begin, end, pinned, index, reach, [&](Eigen::Index v, Eigen::Index a) {
    const Eigen::RowVector3f n = normals.row(a);
    if ((x.row(v) - anchors.row(a)).dot(n) >= within) return false;
    const Eigen::RowVector3f r = (x.row(v) - x_before.row(v)) - (anchors.row(a) - anchors_before.row(a));
    x.row(v) -= mu * (r - r.dot(n) * n);
    return true;
  });
}

// The inner layer's vertices as the layer steps see them, with their k-d tree and normals, rebuilt
// only when the vertices changed: the steps after the body's rarely move the inner layer, and the
// tree costs about as much as the queries it answers.
struct InnerLayer {
  dataset::Points points;  // (outer_begin, 3)
  std::unique_ptr<dataset::NearestVertexIndex> index;
  dataset::Points normals;
  void update(const Eigen::Ref<const dataset::Points>& now, const dataset::Faces& faces) {
    if (index && points == now) return;
    points = now;
    index = std::make_unique<dataset::NearestVertexIndex>(points);
    normals = dataset::vertex_normals(points, faces);
  }
};

}  // namespace

std::vector<std::pair<int32_t, int32_t>> far_corners(const dataset::Faces& faces) {
  std::map<std::pair<int32_t, int32_t>, int32_t> first_opposite;  // edge (u < v) -> corner of its first face
  std::vector<std::pair<int32_t, int32_t>> out;
  for (Eigen::Index f = 0; f < faces.rows(); ++f)
    for (int c = 0; c < 3; ++c) {
      const int32_t a = faces(f, c), b = faces(f, (c + 1) % 3), opposite = faces(f, (c + 2) % 3);
      const auto [it, fresh] = first_opposite.emplace(std::minmax(a, b), opposite);
      if (!fresh && it->second >= 0 && it->second != opposite) {
        out.emplace_back(it->second, opposite);
        it->second = -1;  // a third face on the edge (non-manifold) adds nothing
      }
    }
  return out;
}

ClothConstraints::ClothConstraints(const dataset::SequenceInfo& info, const dataset::Points& rest,
                                   const Eigen::Ref<const dataset::Points>& body_first,
                                   const Eigen::Ref<const dataset::Points>& garments_first, const EvalConfig& settings)
    : settings_(settings), reach_(kReachMetres * info.scale), body_faces_(info.body_faces) {
  const dataset::GarmentEdges edges = dataset::garment_edges(info, rest);
  for (size_t e = 0; e < edges.rows.size(); ++e)
    if (edges.rest[e] > 0) {
      edges_.emplace_back(static_cast<int32_t>(edges.rows[e].first), static_cast<int32_t>(edges.rows[e].second));
      rest_.push_back(static_cast<float>(edges.rest[e]));
    }
  Eigen::Index offset = 0;
  for (const dataset::GarmentMesh& mesh : info.garments) {
    for (const auto& [a, b] : far_corners(mesh.faces)) {
      const float length = (rest.row(offset + a) - rest.row(offset + b)).norm();
      if (length <= 0) continue;
      folds_.emplace_back(static_cast<int32_t>(offset + a), static_cast<int32_t>(offset + b));
      fold_rest_.push_back(length);
    }
    offset += mesh.num_vertices;
  }
  const dataset::GarmentLayout layout = dataset::garment_layout(info);
  outer_begin_ = layout.num_vertices() - layout.outer_vertices();
  if (layout.layered()) inner_faces_ = dataset::inner_faces(layout);
  pinned_.assign(static_cast<size_t>(rest.rows()), 0);
  if (!settings_.pins) return;
  pin_groups_ = dataset::pin_groups(info, garments_first, body_first);
  for (const dataset::PinGroup& group : pin_groups_)
    for (int32_t r : group.rows) pinned_[static_cast<size_t>(r)] = 1;
}

ConstraintMoves ClothConstraints::apply(const Eigen::Ref<const dataset::Points>& body, dataset::Points& x) const {
  return project(body, x, nullptr, nullptr, nullptr);
}

ConstraintMoves ClothConstraints::apply(const Eigen::Ref<const dataset::Points>& body, dataset::Points& x,
                                        const Eigen::Ref<const dataset::Points>& body_before,
                                        const Eigen::Ref<const dataset::Points>& x_before, const dataset::Points* pins_next) const {
  return project(body, x, &body_before, &x_before, pins_next);
}

ConstraintMoves ClothConstraints::project(const Eigen::Ref<const dataset::Points>& body, dataset::Points& x,
                                          const Eigen::Ref<const dataset::Points>* body_before, const Eigen::Ref<const dataset::Points>* x_before,
                                          const dataset::Points* pins_next) const {
  ConstraintMoves moves;
  if (!x.allFinite()) return moves;
  const auto shell = static_cast<float>(settings_.collision_shell);
  const auto mu = static_cast<float>(settings_.body_friction);
  // The pins and the friction move vertices relative to the frame before.
  const bool have_before = body_before && x_before && x_before->rows() == x.rows() && body_before->rows() == body.rows() &&
                           x_before->allFinite();
  const bool friction = (mu > 0 || settings_.layer_friction > 0) && have_before;
  // The body does not move between passes: its normals and k-d tree serve them all.
  std::shared_ptr<const dataset::NearestVertexIndex> body_index;
  dataset::Points body_normals;
  if (shell > 0 || friction) {
    body_index = dataset::NearestVertexIndex::kept(body);
    body_normals = dataset::vertex_normals(body, body_faces_);
  }
  const bool layered = outer_begin_ > 0 && outer_begin_ < x.rows();
  InnerLayer inner_layer;
  if (pins_next && pins_next->rows() == x.rows()) {
    for (const dataset::PinGroup& group : pin_groups_)
      for (int32_t r : group.rows) {
        x.row(r) = pins_next->row(r);
        ++moves.pinned;
      }
  } else if (!pin_groups_.empty() && have_before) {
    moves.pinned += dataset::carry_pins(pin_groups_, *body_before, body, *x_before, x);
  }
  if (friction) {
    const auto within = static_cast<float>(settings_.friction_distance);
    if (mu > 0)
      moves.friction +=
          drag_along(x, *x_before, 0, x.rows(), pinned_, *body_index, body, *body_before, body_normals, within, mu, reach_);
    const auto mu_layer = static_cast<float>(settings_.layer_friction);
    if (mu_layer > 0 && layered) {
      inner_layer.update(x.topRows(outer_begin_), inner_faces_);  // already carried by the body
      moves.friction += drag_along(x, *x_before, outer_begin_, x.rows(), pinned_, *inner_layer.index, inner_layer.points,
                                   x_before->topRows(outer_begin_), inner_layer.normals, within, mu_layer, reach_);
    }
  }
  const auto s = static_cast<float>(settings_.strain_limit), f = static_cast<float>(settings_.fold_limit);
  for (int pass = 0; pass < settings_.constraint_iterations; ++pass) {
    const int64_t moved_before = moves.edges + moves.folds + moves.body + moves.layer;
    if (s > 0)
      for (size_t e = 0; e < edges_.size(); ++e)
        moves.edges += project_pair(x, edges_[e], (1.f - s) * rest_[e], (1.f + s) * rest_[e], rest_[e], pinned_);
    if (f > 0)
      for (size_t q = 0; q < folds_.size(); ++q)
        moves.folds += project_pair(x, folds_[q], (1.f - f) * fold_rest_[q], kUnbounded, fold_rest_[q], pinned_);
    if (shell > 0) {
      moves.body += push_out(x, 0, x.rows(), pinned_, *body_index, body, body_normals, shell, reach_);
      if (layered) {
        inner_layer.update(x.topRows(outer_begin_), inner_faces_);
        moves.layer += push_out(x, outer_begin_, x.rows(), pinned_, *inner_layer.index, inner_layer.points,
                                inner_layer.normals, shell, reach_);
      }
    }
    ++moves.passes;
    // A pass that moved nothing left x as it found it, and so would every later one.
    if (moves.edges + moves.folds + moves.body + moves.layer == moved_before) break;
  }
  return moves;
}

}  // namespace layersnet
