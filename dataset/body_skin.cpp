#include "dataset/body_skin.h"

#include "dataset/neighbours.h"

#include <algorithm>

namespace layersnet::dataset {

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
  out.carriers.assign(static_cast<size_t>(x.rows()), {});
  for (Eigen::Index v = 0; v < x.rows(); ++v) {
    const int32_t h = nearest.index[static_cast<size_t>(v)];
    auto& list = out.carriers[static_cast<size_t>(v)];
    const auto& ring = topology.neighbours[static_cast<size_t>(h)];
    list.reserve(ring.size() + 1);
    double total = 0;
    auto add = [&](int32_t c) {
      const Eigen::Vector3f d = (x.row(v) - body.row(c)).transpose();
      // Squared distance floored at a micro-unit, so a point on the body keeps finite weights.
      const double w = 1.0 / std::max(1e-12, static_cast<double>(d.squaredNorm()));
      SkinBinding::Carrier k;
      k.body_vertex = c;
      k.weight = static_cast<float>(w);
      k.offset = rotate ? Eigen::Vector3f(Eigen::Map<const Eigen::Matrix3f>(frames.row(c).data()).transpose() * d) : d;
      total += w;
      list.push_back(k);
    };
    add(h);
    for (const int32_t c : ring) add(c);
    for (auto& k : list) k.weight = static_cast<float>(k.weight / total);
  }
  return out;
}

Points carry_with_body(const SkinBinding& binding, const Eigen::Ref<const Points>& body, const BodyFrames& frames) {
  Points x(static_cast<Eigen::Index>(binding.carriers.size()), 3);
  for (Eigen::Index v = 0; v < x.rows(); ++v) {
    Eigen::Vector3f p = Eigen::Vector3f::Zero();
    for (const auto& k : binding.carriers[static_cast<size_t>(v)]) {
      Eigen::Vector3f q = body.row(k.body_vertex).transpose();
      if (binding.rotate)
        q += Eigen::Map<const Eigen::Matrix3f>(frames.row(k.body_vertex).data()) * k.offset;
      else
        q += k.offset;
      p += k.weight * q;
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
