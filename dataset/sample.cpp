// Training sample builder (see sample.h for every tensor's definition).
#include "dataset/sample.h"

#include "dataset/wind.h"

#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <map>

namespace layersnet::dataset {
namespace {

// Root-relative positions of all garments at frame f, stacked in layer order: (N, 3).
Points garments_relative(const SequenceInfo& info, const FrameWindow& w, int f, int n_total) {
  Points x(n_total, 3);
  Eigen::Index r = 0;
  for (int g = 0; g < info.num_garments(); ++g) {
    const int n = info.garments[g].num_vertices;
    x.middleRows(r, n) = w.garment_at(g, f, n);
    r += n;
  }
  x.rowwise() -= info.translation.row(f);
  return x;
}

Points body_relative(const SequenceInfo& info, const FrameWindow& w, int f) {
  Points x = w.body_at(f, info.num_body_vertices);
  x.rowwise() -= info.translation.row(f);
  return x;
}

// [p0, v0, p1, v1] -> normalised with position stats on p columns and velocity on v.
RowMatrix normalise_state(const RowMatrix& s, const NormalisationStats& st) {
  Eigen::Matrix<float, 1, 12> mean, inv_std;
  for (int blk = 0; blk < 4; ++blk) {
    const MeanStd& q = blk % 2 == 0 ? st.position : st.velocity;
    mean.segment<3>(3 * blk) = q.mean.cast<float>().transpose();
    inv_std.segment<3>(3 * blk) = q.std.cast<float>().cwiseInverse().transpose();
  }
  return ((s.rowwise() - mean).array().rowwise() * inv_std.array()).matrix();
}

RowMatrix make_state(const Points& p0, const Points& v0, const Points& p1, const Points& v1) {
  RowMatrix s(p0.rows(), 12);
  s << p0, v0, p1, v1;
  return s;
}

Eigen::Vector3f root_velocity(const SequenceInfo& info, int f) {
  return (info.translation.row(f) - info.translation.row(f - 1)).transpose();
}
Eigen::Vector3f root_acceleration(const SequenceInfo& info, int f) {
  return (info.translation.row(f) - 2 * info.translation.row(f - 1) + info.translation.row(f - 2)).transpose();
}

void build_vertex_neighbours(const SequenceInfo& info, SequenceStructure& s) {
  std::vector<std::map<int32_t, float>> adjacent(static_cast<size_t>(s.num_vertices()));
  for (int g = 0; g < info.num_garments(); ++g) {
    const GarmentMesh& mesh = info.garments[g];
    const int32_t offset = s.vertex_offsets[g];
    const bool has_rest = mesh.rest.rows() == mesh.num_vertices;
    for (int f = 0; f < mesh.num_faces(); ++f)
      for (int c = 0; c < 3; ++c) {
        const int a = mesh.faces(f, c), b = mesh.faces(f, (c + 1) % 3);
        const float rest = has_rest ? (mesh.rest.row(a) - mesh.rest.row(b)).norm()
                                    : (mesh.uv.row(3 * f + c) - mesh.uv.row(3 * f + (c + 1) % 3)).norm() * info.scale;
        adjacent[offset + a].emplace(offset + b, rest);
        adjacent[offset + b].emplace(offset + a, rest);
      }
  }
  for (const auto& row : adjacent) {
    for (const auto& [j, rest] : row) s.vertex_neighbours.items.push_back(j), s.neighbour_rest.push_back(rest);
    s.vertex_neighbours.offsets.push_back(static_cast<int32_t>(s.vertex_neighbours.items.size()));
  }
}

// Unit normal of the triangle (p, q, r) as wound (zero when degenerate).
Eigen::Vector3d unit_normal(const Eigen::Vector3d& p, const Eigen::Vector3d& q, const Eigen::Vector3d& r) {
  const Eigen::Vector3d n = (q - p).cross(r - p);
  const double len = n.norm();
  return len > 0 ? Eigen::Vector3d(n / len) : Eigen::Vector3d::Zero();
}

// SequenceStructure::edges and hinges; needs vertex_neighbours (the rest lengths without a template).
void build_edges_and_hinges(const SequenceInfo& info, SequenceStructure& s) {
  struct Side {
    int32_t p, q, opposite;  // directed edge p -> q of a face as wound, and its third vertex
  };
  const Csr& csr = s.vertex_neighbours;
  auto neighbour_rest = [&](int32_t a, int32_t b) {
    for (int32_t k = csr.offsets[a]; k < csr.offsets[a + 1]; ++k)
      if (csr.items[k] == b) return static_cast<double>(s.neighbour_rest[k]);
    return 0.0;
  };
  for (int g = 0; g < info.num_garments(); ++g) {
    const GarmentMesh& mesh = info.garments[g];
    const int32_t o = s.vertex_offsets[g];
    const bool has_rest = mesh.rest.rows() == mesh.num_vertices;
    auto rest = [&](int32_t v) { return Eigen::Vector3d(mesh.rest.row(v).transpose().cast<double>()); };
    std::map<std::pair<int32_t, int32_t>, std::vector<Side>> sides;
    for (int f = 0; f < mesh.num_faces(); ++f)
      for (int c = 0; c < 3; ++c) {
        const int32_t a = mesh.faces(f, c), b = mesh.faces(f, (c + 1) % 3), opposite = mesh.faces(f, (c + 2) % 3);
        sides[{std::min(a, b), std::max(a, b)}].push_back({a, b, opposite});
      }
    for (const auto& [key, list] : sides) {
      const auto [a, b] = key;
      const double length = has_rest ? (rest(a) - rest(b)).norm() : neighbour_rest(o + a, o + b);
      s.edges.push_back({o + a, o + b, g, length});
      if (list.size() != 2) continue;  // boundary (or non-manifold) edge: no hinge
      const Side& A = list[0];
      const Side& B = list[1];
      double cos0 = 1.0, sin0 = 0.0;
      // A face's height over the edge, from its three rest edge lengths (Heron).
      auto height = [&](const Side& f) {
        const double l0 = length;
        const double l1 = has_rest ? (rest(f.q) - rest(f.opposite)).norm() : neighbour_rest(o + f.q, o + f.opposite);
        const double l2 = has_rest ? (rest(f.opposite) - rest(f.p)).norm() : neighbour_rest(o + f.opposite, o + f.p);
        const double s4 = (l0 + l1 + l2) * (-l0 + l1 + l2) * (l0 - l1 + l2) * (l0 + l1 - l2);
        return l0 > 0 ? std::sqrt(std::max(s4, 0.0)) / (2 * l0) : 0.0;
      };
      const double rest_height = hinge_rest_height(height(A), height(B));
      if (has_rest) {
        const Eigen::Vector3d nA = unit_normal(rest(A.p), rest(A.q), rest(A.opposite));
        const Eigen::Vector3d nB = unit_normal(rest(B.p), rest(B.q), rest(B.opposite));
        Eigen::Vector3d e = rest(A.p) - rest(A.q);
        e = e.norm() > 0 ? Eigen::Vector3d(e.normalized()) : e;
        cos0 = nA.dot(nB), sin0 = nA.cross(nB).dot(e);
      } else if (A.p == B.p) {
        cos0 = -1.0;  // inconsistent winding: flat means opposite normals
      }
      s.hinges.push_back({o + A.p, o + A.q, o + A.opposite, o + B.p, o + B.q, o + B.opposite, g, length, cos0, sin0, rest_height});
    }
  }
}

}  // namespace

double hinge_rest_height(double face_height_a, double face_height_b) {
  const double sum = face_height_a + face_height_b;
  return sum > 0 ? 2 * face_height_a * face_height_b / sum : 0.0;
}

Eigen::Matrix<float, 1, 5> normalised_attributes(const GarmentAttributes& g, float body_friction) {
  Eigen::Matrix<float, 1, 5> a;
  a << (g.tension_stiffness - 15.f) / 85.f, (g.bending_stiffness - 15.f) / 185.f, (g.mass - 0.2f) / 0.6f,
      (g.self_friction - 40.f) / 40.f, (body_friction - 40.f) / 40.f;
  return a;
}

std::shared_ptr<const SequenceStructure> build_structure(const SequenceInfo& info, float patch_size) {
  auto s = std::make_shared<SequenceStructure>();
  std::vector<const PatchStructure*> ptrs;
  for (const auto& g : info.garments) s->garments.push_back(build_patches(g, patch_size));
  for (const auto& p : s->garments) ptrs.push_back(&p);
  s->all = concat_patches(ptrs, &s->vertex_offsets, &s->patch_offsets);
  const int G = info.num_garments();
  for (int g = 0; g < G; ++g) {
    s->vertex_garment.insert(s->vertex_garment.end(), s->garments[g].num_vertices, g);
    s->patch_garment.insert(s->patch_garment.end(), s->garments[g].num_patches, g);
    s->garment_types.push_back(info.garments[g].type);
    const auto& f = info.garments[g].faces;
    for (Eigen::Index i = 0; i < f.rows(); ++i)
      for (int c = 0; c < 3; ++c) s->faces.push_back(f(i, c) + s->vertex_offsets[g]);
  }
  std::vector<Eigen::Matrix<float, 1, 5>> rows;
  for (int g = 0; g < G; ++g) {
    const auto a = normalised_attributes(info.garments[g].attributes, info.body_friction);
    auto it = std::find(rows.begin(), rows.end(), a);  // identical vectors share one token
    s->garment_attribute.push_back(static_cast<int32_t>(it - rows.begin()));
    if (it == rows.end()) rows.push_back(a);
  }
  s->attributes.resize(static_cast<Eigen::Index>(rows.size()), 5);
  for (size_t i = 0; i < rows.size(); ++i) s->attributes.row(static_cast<Eigen::Index>(i)) = rows[i];
  build_vertex_neighbours(info, *s);
  build_edges_and_hinges(info, *s);
  s->body = body_topology(info.body_faces, info.num_body_vertices);
  return s;
}

TrainingSample build_sample(const SequenceInfo& info, const FrameWindow& w, int t, const NormalisationStats& st,
                            std::shared_ptr<const SequenceStructure> structure, const SampleOptions& o) {
  if (t < 2 || t + 1 >= info.num_frames)
    throw DatasetError(info.path, "/", "sample frame t = " + std::to_string(t) + " needs frames t-2..t+1 within [0, " +
                                           std::to_string(info.num_frames) + ")");
  if (!w.contains(t - 2) || !w.contains(t + 1))
    throw DatasetError(info.path, "/", "frame window [" + std::to_string(w.first) + ", " +
                                           std::to_string(w.first + w.count) + ") does not hold frames t-2..t+1 for t = " +
                                           std::to_string(t));
  if (!structure) structure = build_structure(info, o.patch_size);
  const SequenceStructure& S = *structure;
  const int N = S.num_vertices();
  TrainingSample s;
  s.sequence_id = info.path;
  s.frame = t;
  s.structure = structure;
  // Garments: frames t-2 .. t+1.
  const Points g0 = garments_relative(info, w, t - 2, N), g1 = garments_relative(info, w, t - 1, N);
  const Points g2 = garments_relative(info, w, t, N), g3 = garments_relative(info, w, t + 1, N);
  const Points v1 = g1 - g0, v2 = g2 - g1, v3 = g3 - g2;
  s.state = make_state(g2, v2, g1, v1);
  s.state_norm = normalise_state(s.state, st);
  s.target.resize(N, 6);
  s.target << g3, v3;
  // Body: frames t-1 .. t+1.
  const Points b1 = body_relative(info, w, t - 1), b2 = body_relative(info, w, t), b3 = body_relative(info, w, t + 1);
  s.body_state = make_state(b3, b3 - b2, b2, b2 - b1);
  s.body_state_norm = normalise_state(s.body_state, st);
  // Patches: means of member states (raw and normalised), target centres.
  s.patch_state = patch_means(S.all, s.state);
  s.patch_state_norm = patch_means(S.all, s.state_norm);
  s.target_patch_centre = patch_means(S.all, g3);
  const Points centres = s.patch_state.leftCols<3>();
  // Root motion, gravity, wind (rows t+1, t).
  s.root_translation = info.translation.row(t).transpose();
  s.root_translation_next = info.translation.row(t + 1).transpose();
  const Eigen::Vector3f g_per_frame = info.gravity / info.fps;  // official g / fps
  for (int row = 0; row < 2; ++row) {
    const int f = t + 1 - row;
    const Eigen::Vector3f rv = root_velocity(info, f), ra = root_acceleration(info, f);
    s.root_motion_norm.row(row).head<3>() =
        ((rv.cast<double>() - st.root_velocity.mean).cwiseQuotient(st.root_velocity.std)).cast<float>().transpose();
    s.root_motion_norm.row(row).tail<3>() =
        ((ra.cast<double>() - st.root_acceleration.mean).cwiseQuotient(st.root_acceleration.std)).cast<float>().transpose();
    s.gravity_norm.row(row) = (((g_per_frame - ra).cast<double>() - st.acceleration.mean)
                                   .cwiseQuotient(st.acceleration.std))
                                  .cast<float>()
                                  .transpose();
  }
  s.has_wind = info.has_wind;
  s.wind.resize(info.has_wind ? 2 : 0, 5);
  if (info.has_wind)
    for (int row = 0; row < 2; ++row) {
      const int f = t + 1 - row;
      s.wind.row(row) << info.wind_rotation.row(f), info.wind_strength[f] / kWindStrengthRange;
      s.wind_rotation[row] = quaternion_matrix(info.wind_rotation.row(f).transpose());
    }
  s.has_layers = info.num_garments() >= 2;
  // Neighbourhoods (dynamic).
  s.world_edges = world_edges(centres, S.all.adjacency, o.neighbours.world_radius);
  s.body_neighbours = body_neighbours(centres, b3, o.neighbours);
  s.body_normals_next = vertex_normals(b3, info.body_faces, info.up_axis == 'y' ? Eigen::Vector3f::UnitY()
                                                                                : Eigen::Vector3f::UnitZ());
  const auto body_index = NearestVertexIndex::kept(b3);
  s.vertex_nearest_body = body_index->query(g2);
  s.patch_nearest_body = body_index->query(centres);
  s.vertex_body_normal.resize(N, 3);
  for (int v = 0; v < N; ++v) s.vertex_body_normal.row(v) = s.body_normals_next.row(s.vertex_nearest_body.index[v]);
  s.patch_body_normal.resize(centres.rows(), 3);
  for (Eigen::Index p = 0; p < centres.rows(); ++p)
    s.patch_body_normal.row(p) = s.body_normals_next.row(s.patch_nearest_body.index[p]);
  if (o.body_carry || o.body_carry_prev) {
    const BodyFrames f2 = body_frames(b2, info.body_faces, S.body);
    if (o.body_carry) {
      s.body_carry = carry_with_body(bind_to_body(g2, b2, f2, S.body), b3, body_frames(b3, info.body_faces, S.body)) - g2;
      smooth_over_mesh(s.body_carry, S.vertex_neighbours, o.carry_smoothing);
    }
    if (o.body_carry_prev) {
      s.body_carry_prev = carry_with_body(bind_to_body(g1, b1, body_frames(b1, info.body_faces, S.body), S.body), b2, f2) - g1;
      smooth_over_mesh(s.body_carry_prev, S.vertex_neighbours, o.carry_smoothing);
    }
  }
  return s;
}

std::vector<int32_t> outer_to_inner_world_edges(const TrainingSample& s) {
  const SequenceStructure& S = *s.structure;
  const int G = static_cast<int>(S.garments.size());
  std::vector<int32_t> counts;
  if (G < 2) return counts;
  const int32_t outer_begin = S.patch_offsets[G - 1];
  for (int32_t p = outer_begin; p < S.patch_offsets[G]; ++p)
    counts.push_back(static_cast<int32_t>(std::count_if(s.world_edges.begin(p), s.world_edges.end(p), [&](int32_t q) {
      return S.patch_garment[q] < G - 1;
    })));
  return counts;
}

std::vector<int> sample_frames(int T, const FrameSelection& sel) {
  const int end = sel.max_frames < 0 ? T : std::min(T, sel.start_frame + sel.max_frames);
  std::vector<int> out;
  for (int t = sel.start_frame + std::max(sel.first_offset, 2); t + 1 < end; ++t) out.push_back(t);
  return out;
}

std::shared_ptr<const SequenceStructure> StructureCache::get(const std::string& id, const SequenceInfo& info) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (auto it = cache_.find(id); it != cache_.end()) return it->second;
  }
  auto s = build_structure(info, patch_size_);
  std::lock_guard<std::mutex> lock(mutex_);
  auto [it, inserted] = cache_.emplace(id, s);
  if (inserted) {
    ++builds_;
    insertion_order_.push_back(id);
    while (cache_.size() > std::max<size_t>(max_entries_, 1)) {
      cache_.erase(insertion_order_.front());
      insertion_order_.erase(insertion_order_.begin());
    }
  }
  return it->second;
}

size_t StructureCache::size() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return cache_.size();
}

}  // namespace layersnet::dataset
