#include "dataset/body_skin.h"

#include "dataset/neighbours.h"

#include <algorithm>

namespace layersnet::dataset {
namespace {
// Each point's (or body vertex's) result is its own, so the threads change no bit; below this many
// rows a fork costs more than the loop.
constexpr Eigen::Index kParallelRows = 512;
}  // namespace

BodyTopology body_topology(const Faces& faces, int num_body_vertices) {
  BodyTopology t;
  t.neighbours.assign(static_cast<size_t>(num_body_vertices), {});
  for (Eigen::Index i = 0; i < faces.rows(); ++i)
    for (int k = 0; k < 3; ++k) {
      auto& list = t.neighbours[static_cast<size_t>(faces(i, k))];
      list.push_back(faces(i, (k + 1) % 3));
      list.push_back(faces(i, (k + 2) % 3));
    }
  for (auto& n : t.neighbours) {
    std::sort(n.begin(), n.end());
    n.erase(std::unique(n.begin(), n.end()), n.end());
  }
  t.tangent_neighbour.resize(t.neighbours.size());
  for (size_t i = 0; i < t.neighbours.size(); ++i)
    t.tangent_neighbour[i] = t.neighbours[i].empty() ? static_cast<int32_t>(i) : t.neighbours[i].front();
  return t;
}

BodyFrames body_frames(const Eigen::Ref<const Points>& body, const Faces& faces, const BodyTopology& topology) {
  const Points normals = vertex_normals(body, faces);
  BodyFrames frames(body.rows(), 9);
#pragma omp parallel for schedule(static) if (body.rows() > kParallelRows)
  for (Eigen::Index i = 0; i < body.rows(); ++i) {
    const Eigen::Vector3f n = normals.row(i).transpose();
    Eigen::Vector3f u = (body.row(topology.tangent_neighbour[static_cast<size_t>(i)]) - body.row(i)).transpose();
    u -= u.dot(n) * n;
    if (!(u.norm() > 1e-12f)) u = n.unitOrthogonal();  // an isolated vertex: any tangent, kept consistent
    u.normalize();
    const Eigen::Vector3f b = n.cross(u);
    frames.row(i) << u.transpose(), b.transpose(), n.transpose();
  }
  return frames;
}

SkinBinding bind_to_body(const Eigen::Ref<const Points>& x, const Eigen::Ref<const Points>& body,
                         const BodyFrames& frames, const BodyTopology& topology, bool rotate) {
  const NearestBody nearest = NearestVertexIndex::kept(body)->query(x);
  SkinBinding out;
  out.rotate = rotate;
  const Eigen::Index Q = x.rows();
  // A point's carriers are its nearest body vertex and that vertex's ring: their count is known
  // first, so the points then fill their own slots on the threads, with no allocation each.
  out.offsets.resize(static_cast<size_t>(Q) + 1);
  out.offsets[0] = 0;
  for (size_t v = 0; v < static_cast<size_t>(Q); ++v) {
    const auto& ring = topology.neighbours[static_cast<size_t>(nearest.index[v])];
    out.offsets[v + 1] = out.offsets[v] + static_cast<int32_t>(ring.size()) + 1;
  }
  out.carriers.resize(static_cast<size_t>(out.offsets.back()));
#pragma omp parallel for schedule(static) if (Q > kParallelRows)
  for (Eigen::Index v = 0; v < Q; ++v) {
    const int32_t h = nearest.index[static_cast<size_t>(v)];
    SkinBinding::Carrier* const first = out.carriers.data() + out.offsets[static_cast<size_t>(v)];
    SkinBinding::Carrier* next = first;
    double total = 0;
    auto add = [&](int32_t c) {
      const Eigen::Vector3f d = (x.row(v) - body.row(c)).transpose();
      // Squared distance floored at a micro-unit, so a point on the body keeps finite weights.
      const double w = 1.0 / std::max(1e-12, static_cast<double>(d.squaredNorm()));
      next->body_vertex = c;
      next->weight = static_cast<float>(w);
      next->offset =
          rotate ? Eigen::Vector3f(Eigen::Map<const Eigen::Matrix3f>(frames.row(c).data()).transpose() * d) : d;
      total += w;
      ++next;
    };
    add(h);
    for (const int32_t c : topology.neighbours[static_cast<size_t>(h)]) add(c);
    for (SkinBinding::Carrier* k = first; k != next; ++k) k->weight = static_cast<float>(k->weight / total);
  }
  return out;
}

Points carry_with_body(const SkinBinding& binding, const Eigen::Ref<const Points>& body, const BodyFrames& frames) {
  Points x(binding.points(), 3);
#pragma omp parallel for schedule(static) if (x.rows() > kParallelRows)
  for (Eigen::Index v = 0; v < x.rows(); ++v) {
    Eigen::Vector3f p = Eigen::Vector3f::Zero();
    for (int32_t k = binding.offsets[static_cast<size_t>(v)]; k < binding.offsets[static_cast<size_t>(v) + 1]; ++k) {
      const SkinBinding::Carrier& c = binding.carriers[static_cast<size_t>(k)];
      Eigen::Vector3f q = body.row(c.body_vertex).transpose();
      if (binding.rotate)
        q += Eigen::Map<const Eigen::Matrix3f>(frames.row(c.body_vertex).data()) * c.offset;
      else
        q += c.offset;
      p += c.weight * q;
    }
    x.row(v) = p.transpose();
  }
  return x;
}

void smooth_over_mesh(Points& u, const Csr& neighbours, int iterations) {
  if (iterations <= 0) return;  // the default: no buffer on every sample's path
  Points next(u.rows(), 3);
  for (int it = 0; it < iterations; ++it) {
    for (int v = 0; v < neighbours.rows(); ++v) {
      Eigen::RowVector3f mean = u.row(v);  // an isolated vertex keeps its value
      if (neighbours.size(v) > 0) {
        mean.setZero();
        for (const int32_t* n = neighbours.begin(v); n != neighbours.end(v); ++n) mean += u.row(*n);
        mean /= static_cast<float>(neighbours.size(v));
      }
      next.row(v) = 0.5f * (u.row(v) + mean);
    }
    u.swap(next);
  }
}

}  // namespace layersnet::dataset
