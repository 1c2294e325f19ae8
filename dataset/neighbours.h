#pragma once
// Neighbourhoods without all-pairs work (as the official code), and body vertex normals (official utils/mesh3d.py).
//
// All queries go through a uniform spatial hash grid whose cell equals the query radius
// (each query visits 27 cells), or a k-d tree (nanoflann) for unbounded nearest-vertex
// queries; cost is O((queries + points) * local density), linear in the vertex count for
// meshes of fixed density (`layersnet bench neighbours` shows it).
//
// Distances are in scene units; comparisons are strict (< radius), as the official code.
#include "dataset/patches.h"
#include "dataset/sequence.h"

#include <Eigen/Core>

#include <cmath>
#include <cstdint>
#include <memory>
#include <vector>

namespace layersnet::dataset {

// Per-vertex normals: normalised sum of the incident faces' unit normals, face normal
// (v1 - v0) x (v2 - v0) (counter-clockwise = outward). Zero-area faces add nothing; a vertex
// with no usable face gets `fallback`. Always finite. x: (V, 3), faces (F, 3) -> (V, 3).
// The double form serves the loss targets (float positions, normals summed in double).
using PointsD = Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor>;  // (rows, 3)
Points vertex_normals(const Eigen::Ref<const Points>& x, const Faces& faces,
                      const Eigen::Vector3f& fallback = Eigen::Vector3f::UnitZ());
PointsD vertex_normals(const Eigen::Ref<const PointsD>& x, const Faces& faces,
                       const Eigen::Vector3d& fallback = Eigen::Vector3d::UnitZ());

// Uniform hash grid over a point set; radius queries visit the 27 cells around a point.
class PointGrid {
 public:
  PointGrid(const Eigen::Ref<const Points>& points, float cell);
  // Calls fn(index, squared distance) for every point strictly within `radius` (<= cell) of q,
  // in ascending cell order (not index order).
  template <typename Fn>
  void for_each_within(const Eigen::Vector3f& q, float radius, Fn&& fn) const;
  float cell() const { return cell_; }

 private:
  struct Bucket {
    int64_t key;
    int32_t begin, end;
  };
  int64_t key_of(int64_t i, int64_t j, int64_t k) const;
  const Bucket* find(int64_t key) const;
  Points points_;                  // copy: the grid owns its points
  float cell_;
  std::vector<int32_t> order_;     // point ids sorted by cell key (stable)
  std::vector<Bucket> buckets_;    // sorted by key
};

// How body neighbours of a patch are chosen among the body vertices within R_b.
enum class BodyQuery {
  kFirstInIndexOrder,  // official mmcv ball_query: the K lowest vertex indices inside R_b
  kNearest,            // the K nearest vertices inside R_b
};

struct NeighbourOptions {
  float world_radius = 0.4f;  // R: patch-centre distance for world edges
  float body_radius = 0.6f;   // R_b
  int body_k = 16;            // K
  BodyQuery body_query = BodyQuery::kFirstInIndexOrder;
  // Official padding: unfilled slots repeat the first hit (vertex 0 when none) and count as
  // valid when within R_b, so duplicates weigh several times. false: padding is invalid.
  bool official_padding = true;
};

// World edges: for every patch i, the patches j != i with |c_i - c_j| < radius that are not
// in mesh_adjacency row i. centres (P, 3); mesh_adjacency has P rows. Rows ascending.
Csr world_edges(const Eigen::Ref<const Points>& centres, const Csr& mesh_adjacency, float radius);

struct BodyNeighbours {
  int k = 0;
  // index (P, K): body vertex ids; valid (P, K): 1 where the slot is a neighbour (< R_b).
  Eigen::Matrix<int32_t, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> index;
  Eigen::Matrix<uint8_t, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> valid;
  std::vector<int32_t> hits;  // (P,) distinct body vertices found (<= K)
};

// Up to K body vertices within R_b of each query point (patch centres at t, body at t+1 in
// the official code). queries (P, 3), body (B, 3).
BodyNeighbours body_neighbours(const Eigen::Ref<const Points>& queries, const Eigen::Ref<const Points>& body,
                               const NeighbourOptions& options = {});

// Nearest body vertex of each query point (k-d tree; unbounded distance).
struct NearestBody {
  std::vector<int32_t> index;  // (Q,)
  std::vector<float> distance; // (Q,) Euclidean, scene units
};
NearestBody nearest_body(const Eigen::Ref<const Points>& queries, const Eigen::Ref<const Points>& body);

// The same k-d tree kept for many query sets against one fixed point set (copied): building it
// costs about as much as querying every point once. query() gives what nearest_body gives.
class NearestVertexIndex {
 public:
  explicit NearestVertexIndex(const Eigen::Ref<const Points>& points);
  ~NearestVertexIndex();
  NearestVertexIndex(const NearestVertexIndex&) = delete;
  NearestVertexIndex& operator=(const NearestVertexIndex&) = delete;
  // A thread that asks again about the points it asked about last (the physics step: its
  // friction's contacts, then its energy at the same start) gets the answer it was given.
  NearestBody query(const Eigen::Ref<const Points>& queries) const;
  // The nearest point within max_distance (scene units) of each query, else index 0 and
  // distance +inf. Where it finds one it equals query(); the bound prunes the tree walk, which
  // costs far less when most queries only ask whether a point is near. The calling thread's last
  // answers for as many queries against as many points start the walks: faster where the queries
  // moved little, and the same answers.
  NearestBody query_within(const Eigen::Ref<const Points>& queries, float max_distance) const;
  // The index of `points` from the calling thread's last few, built only when these points (by
  // value) are not among them: a rollout asks for each body frame's index several times (the
  // sample, the physics step, the post-processing, the next frame's sample). A kept index is the
  // one a build would give.
  static std::shared_ptr<const NearestVertexIndex> kept(const Eigen::Ref<const Points>& points);

 private:
  struct Tree;
  std::unique_ptr<Tree> tree_;
  uint64_t id_;  // unique in the process: what query()'s kept answer belongs to (an address may be reused)
};

// ---- template implementation
// Grid cell of a coordinate, clamped so that absurd (but finite) positions stay defined.
inline int64_t grid_cell(float x, float cell) {
  const double c = std::floor(static_cast<double>(x) / static_cast<double>(cell));
  return static_cast<int64_t>(c < -1e15 ? -1e15 : c > 1e15 ? 1e15 : c);
}

template <typename Fn>
void PointGrid::for_each_within(const Eigen::Vector3f& q, float radius, Fn&& fn) const {
  const float r2 = radius * radius;
  const int64_t ci = grid_cell(q.x(), cell_), cj = grid_cell(q.y(), cell_), ck = grid_cell(q.z(), cell_);
  for (int64_t di = -1; di <= 1; ++di)
    for (int64_t dj = -1; dj <= 1; ++dj)
      for (int64_t dk = -1; dk <= 1; ++dk) {
        const Bucket* b = find(key_of(ci + di, cj + dj, ck + dk));
        if (!b) continue;
        for (int32_t n = b->begin; n < b->end; ++n) {
          const int32_t id = order_[n];
          const float d2 = (points_.row(id).transpose() - q).squaredNorm();
          if (d2 < r2) fn(id, d2);
        }
      }
}

}  // namespace layersnet::dataset
