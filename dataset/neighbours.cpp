// Spatial hash grid, k-d tree nearest queries, world edges, body ball queries, normals.
#include "dataset/neighbours.h"

#include "dataset/kept.h"

#include <nanoflann.hpp>

#include <algorithm>
#include <atomic>
#include <cmath>

namespace layersnet::dataset {

namespace {

template <class Scalar>
Eigen::Matrix<Scalar, Eigen::Dynamic, 3, Eigen::RowMajor> normals_of(
    const Eigen::Ref<const Eigen::Matrix<Scalar, Eigen::Dynamic, 3, Eigen::RowMajor>>& x, const Faces& faces,
    const Eigen::Matrix<Scalar, 3, 1>& fallback) {
  using Vec = Eigen::Matrix<Scalar, 3, 1>;
  Eigen::Matrix<Scalar, Eigen::Dynamic, 3, Eigen::RowMajor> n =
      Eigen::Matrix<Scalar, Eigen::Dynamic, 3, Eigen::RowMajor>::Zero(x.rows(), 3);
  for (Eigen::Index f = 0; f < faces.rows(); ++f) {
    const Vec a = x.row(faces(f, 0)), b = x.row(faces(f, 1)), c = x.row(faces(f, 2));
    const Vec fn = (b - a).cross(c - a);
    const Scalar len = fn.norm();
    if (!(len > Scalar(1e-20f)) || !std::isfinite(len)) continue;  // zero-area face: no direction
    const Eigen::Matrix<Scalar, 1, 3> unit = (fn / len).transpose();
    for (int k = 0; k < 3; ++k) n.row(faces(f, k)) += unit;
  }
  for (Eigen::Index v = 0; v < n.rows(); ++v) {
    const Scalar len = n.row(v).norm();
    if (len > Scalar(1e-12f) && std::isfinite(len))
      n.row(v) /= len;
    else
      n.row(v) = fallback.transpose();
  }
  return n;
}

}  // namespace

Points vertex_normals(const Eigen::Ref<const Points>& x, const Faces& faces, const Eigen::Vector3f& fallback) {
  return normals_of<float>(x, faces, fallback);
}

PointsD vertex_normals(const Eigen::Ref<const PointsD>& x, const Faces& faces, const Eigen::Vector3d& fallback) {
  return normals_of<double>(x, faces, fallback);
}

int64_t PointGrid::key_of(int64_t i, int64_t j, int64_t k) const {
  // 21 bits per axis; wrapped cells only add candidates (distances are always checked).
  constexpr int64_t mask = (int64_t{1} << 21) - 1;
  return ((i & mask) << 42) | ((j & mask) << 21) | (k & mask);
}

PointGrid::PointGrid(const Eigen::Ref<const Points>& points, float cell) : points_(points), cell_(cell) {
  const int32_t n = static_cast<int32_t>(points_.rows());
  std::vector<std::pair<int64_t, int32_t>> keyed(n);
  for (int32_t i = 0; i < n; ++i) {
    const auto p = points_.row(i);
    keyed[i] = {key_of(grid_cell(p.x(), cell_), grid_cell(p.y(), cell_), grid_cell(p.z(), cell_)), i};
  }
  std::sort(keyed.begin(), keyed.end());  // by key, then index
  order_.resize(n);
  for (int32_t i = 0; i < n; ++i) {
    order_[i] = keyed[i].second;
    if (i == 0 || keyed[i].first != keyed[i - 1].first) buckets_.push_back({keyed[i].first, i, i + 1});
    else buckets_.back().end = i + 1;
  }
}

const PointGrid::Bucket* PointGrid::find(int64_t key) const {
  auto it = std::lower_bound(buckets_.begin(), buckets_.end(), key,
                             [](const Bucket& b, int64_t k) { return b.key < k; });
  return it != buckets_.end() && it->key == key ? &*it : nullptr;
}

Csr world_edges(const Eigen::Ref<const Points>& centres, const Csr& mesh_adjacency, float radius) {
  const int P = static_cast<int>(centres.rows());
  const PointGrid grid(centres, radius);
  std::vector<std::vector<int32_t>> rows(P);
#pragma omp parallel for schedule(dynamic, 64) if (P > 2048)
  for (int i = 0; i < P; ++i) {
    grid.for_each_within(centres.row(i).transpose(), radius, [&](int32_t j, float) {
      if (j != i && !std::binary_search(mesh_adjacency.begin(i), mesh_adjacency.end(i), j)) rows[i].push_back(j);
    });
    std::sort(rows[i].begin(), rows[i].end());
  }
  Csr out;
  out.offsets.resize(static_cast<size_t>(P) + 1);
  for (int i = 0; i < P; ++i) out.offsets[i + 1] = out.offsets[i] + static_cast<int32_t>(rows[i].size());
  out.items.reserve(out.offsets.back());
  for (auto& r : rows) out.items.insert(out.items.end(), r.begin(), r.end());
  return out;
}

BodyNeighbours body_neighbours(const Eigen::Ref<const Points>& queries, const Eigen::Ref<const Points>& body,
                               const NeighbourOptions& o) {
  const int Q = static_cast<int>(queries.rows()), K = o.body_k;
  BodyNeighbours out;
  out.k = K;
  out.index.setZero(Q, K);
  out.valid.setZero(Q, K);
  out.hits.assign(Q, 0);
  if (Q == 0 || K <= 0) return out;
  const PointGrid grid(body, o.body_radius);
#pragma omp parallel if (Q > 2048)
  {
    std::vector<std::pair<float, int32_t>> found;  // (key, id): key = index or distance
#pragma omp for schedule(dynamic, 64)
    for (int q = 0; q < Q; ++q) {
      found.clear();
      grid.for_each_within(queries.row(q).transpose(), o.body_radius, [&](int32_t id, float d2) {
        found.emplace_back(o.body_query == BodyQuery::kNearest ? d2 : 0.f, id);
      });
      const size_t n = std::min<size_t>(found.size(), static_cast<size_t>(K));
      // Official: lowest indices first; nearest: smallest distance (ties by index).
      std::partial_sort(found.begin(), found.begin() + static_cast<std::ptrdiff_t>(n), found.end());
      out.hits[q] = static_cast<int32_t>(n);
      for (size_t s = 0; s < n; ++s) {
        out.index(q, static_cast<Eigen::Index>(s)) = found[s].second;
        out.valid(q, static_cast<Eigen::Index>(s)) = 1;
      }
      for (int s = static_cast<int>(n); s < K; ++s) {
        out.index(q, s) = n ? found[0].second : 0;
        out.valid(q, s) = o.official_padding && n ? 1 : 0;
      }
    }
  }
  return out;
}

namespace {
struct PointsAdaptor {
  const Points& p;
  size_t kdtree_get_point_count() const { return static_cast<size_t>(p.rows()); }
  float kdtree_get_pt(size_t i, size_t d) const { return p(static_cast<Eigen::Index>(i), static_cast<Eigen::Index>(d)); }
  template <class Box>
  bool kdtree_get_bbox(Box&) const { return false; }
};
using KdTree = nanoflann::KDTreeSingleIndexAdaptor<nanoflann::L2_Simple_Adaptor<float, PointsAdaptor>, PointsAdaptor, 3,
                                                   uint32_t>;
std::atomic<uint64_t> next_index_id{1};  // NearestVertexIndex ids
}  // namespace

struct NearestVertexIndex::Tree {
  explicit Tree(const Eigen::Ref<const Points>& p)
      : points(p), adaptor{points}, kd(3, adaptor, nanoflann::KDTreeSingleIndexAdaptorParams(16)) {}  // builds itself
  Points points;
  PointsAdaptor adaptor;
  KdTree kd;
};

NearestVertexIndex::NearestVertexIndex(const Eigen::Ref<const Points>& points)
    : tree_(std::make_unique<Tree>(points)), id_(next_index_id.fetch_add(1, std::memory_order_relaxed)) {}
NearestVertexIndex::~NearestVertexIndex() = default;

NearestBody NearestVertexIndex::query(const Eigen::Ref<const Points>& queries) const {
  struct Asked {
    uint64_t index = 0;  // ids start at 1
    Points points;
    NearestBody answer;
  };
  thread_local Asked last;
  if (last.index == id_ && last.points.rows() == queries.rows() && last.points == queries) return last.answer;
  NearestBody answer = query_within(queries, std::numeric_limits<float>::infinity());
  last.index = id_;
  last.points = queries;
  last.answer = answer;
  return answer;
}

namespace {

// The answers a thread was last given for queries of this many rows against this many points: the
// starting guesses of its next such walk (a rollout asks about the same cloth vertices against each
// body frame several times a frame, and the cloth moves little between asks).
struct LastAnswer {
  Eigen::Index queries = 0, points = 0;
  std::vector<int32_t> index;
};

}  // namespace

NearestBody NearestVertexIndex::query_within(const Eigen::Ref<const Points>& queries, float max_distance) const {
  NearestBody out;
  const Eigen::Index Q = queries.rows(), P = tree_->points.rows();
  out.index.assign(Q, 0);
  out.distance.assign(Q, std::numeric_limits<float>::infinity());
  if (P == 0) return out;
  // Slightly above max_distance², so that a point at exactly max_distance is found; the walk
  // only adds points strictly closer than the current bound.
  const float bound = std::isfinite(max_distance) ? std::nextafter(max_distance * max_distance, std::numeric_limits<float>::max())
                                                  : std::numeric_limits<float>::max();
  // A guess (the point this thread was last given for the same row) tightens the walk's starting
  // bound to a little above the guess's distance, which prunes most of the tree at once. The answer
  // is the one a walk from `bound` gives: that answer is the first point at the least distance in
  // the walk's order, the order does not depend on the bound, and no subtree holding a point at
  // the least distance is pruned while the bound stays above it (the slack covers the rounding of
  // the walk's box distances).
  thread_local std::vector<std::shared_ptr<const LastAnswer>> recent;
  const auto last = kept_or_made(
      recent, 4, [&](const LastAnswer& a) { return a.queries == Q && a.points == P; },
      [&] { return std::make_shared<const LastAnswer>(LastAnswer{Q, P, {}}); });
  const bool guessed = static_cast<Eigen::Index>(last->index.size()) == Q;
  const Points& points = tree_->points;
  // A query costs about a microsecond; from a few hundred on, a second thread pays on a machine
  // whose cores are free (on one loaded by other processes it may not: docs/decisions.md,
  // "Nearest-vertex queries on the threads again").
#pragma omp parallel for schedule(static) if (Q > 512)
  for (Eigen::Index q = 0; q < Q; ++q) {
    const float pt[3] = {queries(q, 0), queries(q, 1), queries(q, 2)};
    float start = bound;
    if (guessed) {
      const int32_t g = last->index[q];
      float d2 = 0;
      for (int c = 0; c < 3; ++c) d2 += (pt[c] - points(g, c)) * (pt[c] - points(g, c));
      start = std::min(bound, std::max(d2 * 1.001f, std::numeric_limits<float>::min()));
    }
    uint32_t idx = 0;
    float d2 = 0;
    nanoflann::KNNResultSet<float, uint32_t> result(1);
    result.init(&idx, &d2);
    d2 = start;  // the walk's initial worst distance
    tree_->kd.findNeighbors(result, pt, nanoflann::SearchParams());
    if (result.size() == 0) continue;
    out.index[q] = static_cast<int32_t>(idx);
    out.distance[q] = std::sqrt(d2);
  }
  recent.front() = std::make_shared<const LastAnswer>(LastAnswer{Q, P, out.index});
  return out;
}

std::shared_ptr<const NearestVertexIndex> NearestVertexIndex::kept(const Eigen::Ref<const Points>& points) {
  thread_local std::vector<std::shared_ptr<const NearestVertexIndex>> recent;
  return kept_or_made(
      recent, 4,
      [&](const NearestVertexIndex& index) {
        const Points& p = index.tree_->points;
        return p.rows() == points.rows() && (points.rows() == 0 || p == points);
      },
      [&] { return std::make_shared<const NearestVertexIndex>(points); });
}

NearestBody nearest_body(const Eigen::Ref<const Points>& queries, const Eigen::Ref<const Points>& body) {
  return NearestVertexIndex(body).query(queries);
}

}  // namespace layersnet::dataset
