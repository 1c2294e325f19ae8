#include "model/sample_input.h"

#include "autodiff/check.h"
#include "dataset/wind.h"

#include <algorithm>
#include <array>
#include <cmath>

namespace layersnet::model {
namespace {

using Vec3 = std::array<double, 3>;

Vec3 row3(const std::vector<double>& x, int64_t i) { return {x[3 * i], x[3 * i + 1], x[3 * i + 2]}; }
double dist2(const Vec3& a, const Vec3& b) {
  double s = 0;
  for (int c = 0; c < 3; ++c) s += (a[c] - b[c]) * (a[c] - b[c]);
  return s;
}
Vec3 cross(const Vec3& a, const Vec3& b) {
  return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
}
Vec3 normalized(Vec3 v) {
  double n = std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
  if (n < 1e-12) return {0, 0, 0};
  return {v[0] / n, v[1] / n, v[2] / n};
}

void csr_copy(const dataset::Csr& c, std::vector<int32_t>& offsets, std::vector<int32_t>& items) {
  offsets = c.offsets;
  items = c.items;
}

template <class M>
std::vector<float> flat(const M& m) {
  std::vector<float> out(static_cast<std::size_t>(m.rows() * m.cols()));
  for (Eigen::Index i = 0; i < m.rows(); ++i)
    for (Eigen::Index j = 0; j < m.cols(); ++j) out[i * m.cols() + j] = static_cast<float>(m(i, j));
  return out;
}

// ModelInput::vertex_local (N, 21), world axes, scaled by 1/R_b (lengths) and 1/σ_v (velocities).
std::vector<float> vertex_local_features(const dataset::TrainingSample& s, float body_radius, float sigma_v) {
  const auto& nb = s.structure->vertex_neighbours;
  const auto& rest = s.structure->neighbour_rest;
  const int64_t N = s.num_vertices();
  std::vector<float> out(static_cast<std::size_t>(N * kVertexLocalDim), 0.f);
  const float inv_r = 1.f / body_radius, inv_v = 1.f / sigma_v;
  for (int64_t v = 0; v < N; ++v) {
    float* f = &out[static_cast<std::size_t>(v * kVertexLocalDim)];
    const Eigen::Vector3f x = s.state.row(v).segment<3>(0), vel = s.state.row(v).segment<3>(3);
    const Eigen::Vector3f vel_prev = s.state.row(v).segment<3>(9);
    auto put = [&](int block, const Eigen::Vector3f& a, float scale) {
      for (int c = 0; c < 3; ++c) f[3 * block + c] = a[c] * scale;
    };
    if (s.vertex_nearest_body.distance[v] < body_radius) {
      const auto b = s.body_state.row(s.vertex_nearest_body.index[v]);
      const Eigen::Vector3f b_vel_next = b.segment<3>(3), b_x = b.segment<3>(6), b_vel = b.segment<3>(9);
      put(0, x - b_x, inv_r);
      put(1, b_vel_next - vel, inv_v);
      put(2, b_vel_next - b_vel, inv_v);
    }
    Eigen::Vector3f spring = Eigen::Vector3f::Zero(), lap = Eigen::Vector3f::Zero(), lap_vel = Eigen::Vector3f::Zero();
    for (int32_t k = nb.offsets[v]; k < nb.offsets[v + 1]; ++k) {
      const int32_t j = nb.items[k];
      const Eigen::Vector3f e = s.state.row(j).segment<3>(0).transpose() - x;
      const float length = e.norm();
      if (length > 0) spring += (length - rest[k]) / length * e;
      lap += e;
      lap_vel += s.state.row(j).segment<3>(3).transpose() - vel;
    }
    const int degree = nb.size(static_cast<int>(v));
    if (degree > 0) lap /= static_cast<float>(degree), lap_vel /= static_cast<float>(degree);
    put(3, spring, inv_r);
    put(4, lap, inv_r);
    put(5, lap_vel, inv_v);
    put(6, vel - vel_prev, inv_v);
  }
  return out;
}

// ModelInput::wind_force (N, 3): the face wind of the wind at t+1, w = (strength / 400) × its unit
// direction, at x_t, per unit of the garment's mean vertex area share (Blender's vertices carry
// equal masses, so this is the wind's acceleration up to one constant per garment).
std::vector<float> wind_force_feature(const dataset::TrainingSample& s) {
  const dataset::SequenceStructure& S = *s.structure;
  // The wind blows along R(q)'s z axis (dataset::wind_direction); the sample holds R(q) of t+1.
  const Eigen::Vector3d w = static_cast<double>(s.wind(0, 4)) * s.wind_rotation[0].col(2).cast<double>();
  Eigen::VectorXd area;
  const dataset::Points force = dataset::face_wind_force(s.state.leftCols<3>(), S.faces, w, &area);
  std::vector<float> out(static_cast<std::size_t>(3 * force.rows()));
  for (std::size_t g = 0; g + 1 < S.vertex_offsets.size(); ++g) {
    const int begin = S.vertex_offsets[g], end = S.vertex_offsets[g + 1];
    const double mean_area = end > begin ? area.segment(begin, end - begin).mean() : 0.0;
    const double scale = mean_area > 0 ? 1.0 / mean_area : 0.0;
    for (int v = begin; v < end; ++v)
      for (int c = 0; c < 3; ++c) out[3 * v + c] = static_cast<float>(force(v, c) * scale);
  }
  return out;
}

}  // namespace

dataset::SampleOptions sample_options_for(const ModelConfig& m) {
  dataset::SampleOptions o;
  o.patch_size = static_cast<float>(m.patch_size);
  o.neighbours.world_radius = static_cast<float>(m.world_radius);
  o.neighbours.body_radius = static_cast<float>(m.body_radius);
  o.neighbours.body_k = m.body_neighbors;
  o.neighbours.body_query =
      m.body_query == "first" ? dataset::BodyQuery::kFirstInIndexOrder : dataset::BodyQuery::kNearest;
  // The model keeps valid slots only (model/README.md quirk 3), so no duplicate padding.
  o.neighbours.official_padding = false;
  o.body_carry = m.velocity_base != "inertia";
  o.body_carry_prev =
      m.velocity_base == "body_inertia" || (m.velocity_base == "physics" && m.physics_step_inertia == "body");
  o.carry_smoothing = m.carry_smoothing;
  return o;
}

void normal_frame(const double normal[3], double R[9]) {
  const Vec3 n_in{normal[0], normal[1], normal[2]};
  Vec3 n = normalized(n_in);
  if (n[0] == 0 && n[1] == 0 && n[2] == 0) {
    for (int k = 0; k < 9; ++k) R[k] = (k % 4 == 0) ? 1.0 : 0.0;
    return;
  }
  Vec3 x0{1, 0, 0};
  for (int c = 0; c < 3; ++c)
    if (std::abs(n[c]) < 1e-7) x0[c] = 1;
  double d = x0[0] * n[0] + x0[1] * n[1] + x0[2] * n[2];
  Vec3 x = normalized({x0[0] - d * n[0], x0[1] - d * n[1], x0[2] - d * n[2]});
  if (x[0] == 0 && x[1] == 0 && x[2] == 0) x = normalized(cross(n, {0, 1, 0}));  // n = ±(1,1,1)/√3 never hits this; n ∥ x0 can
  Vec3 y = cross(n, x);
  for (int c = 0; c < 3; ++c) R[c] = x[c], R[3 + c] = y[c], R[6 + c] = n[c];
}

void decoder_candidates(const std::vector<double>& xt, const std::vector<double>& centre,
                        const std::vector<int32_t>& own_patch, const std::vector<int32_t>& adj_offsets,
                        const std::vector<int32_t>& adj_patches, int k_cand, std::vector<int32_t>& offsets,
                        std::vector<int32_t>& items) {
  const int64_t N = static_cast<int64_t>(own_patch.size());
  offsets.assign(1, 0);
  items.clear();
  std::vector<std::pair<double, int32_t>> c;
  for (int64_t v = 0; v < N; ++v) {
    const int32_t own = own_patch[v];
    if (own >= 0) {
      c.clear();
      for (int32_t k = adj_offsets[own]; k < adj_offsets[own + 1]; ++k) {
        const int32_t p = adj_patches[k];
        c.emplace_back(std::sqrt(dist2(row3(xt, v), row3(centre, p))), p);
      }
      const std::size_t kk = std::min<std::size_t>(c.size(), static_cast<std::size_t>(k_cand));
      std::partial_sort(c.begin(), c.begin() + kk, c.end());
      for (std::size_t j = 0; j < kk; ++j) {
        const int32_t p = c[j].second;
        const double pd = std::sqrt(dist2(row3(centre, own), row3(centre, p)));
        if (p == own || pd == 0 || c[j].first < pd) items.push_back(p);
      }
    }
    offsets.push_back(static_cast<int32_t>(items.size()));
  }
}

ModelInput<float> model_input_from_sample(const dataset::TrainingSample& s, const dataset::NormalisationStats& stats,
                                          const ModelConfig& cfg) {
  LAYERSNET_CHECK(s.structure != nullptr, "TrainingSample '" << s.sequence_id << "' frame " << s.frame
                                                             << " has no structure; build it with build_sample()");
  const auto& st = *s.structure;
  const int64_t N = s.num_vertices(), P = s.num_patches(), B = s.body_state.rows();
  ModelInput<float> in;
  in.N = N, in.P = P, in.A = st.attributes.rows();
  in.state = flat(s.state), in.state_norm = flat(s.state_norm);
  csr_copy(st.all.vertex_patches, in.v2p_offsets, in.v2p_patches);
  csr_copy(st.all.patch_vertices, in.p2v_offsets, in.p2v_vertices);
  csr_copy(st.all.adjacency, in.mesh_offsets, in.mesh_senders);
  csr_copy(s.world_edges, in.world_offsets, in.world_senders);
  in.own_patch = st.all.own_patch;
  in.patch_state = flat(s.patch_state), in.patch_norm = flat(s.patch_state_norm);
  in.attr = flat(st.attributes);
  in.patch_attr.resize(P);
  for (int64_t p = 0; p < P; ++p) in.patch_attr[p] = st.garment_attribute[st.patch_garment[p]];

  // Body tokens: referenced vertices, in ascending vertex order.
  std::vector<int32_t> remap(B, -1);
  std::vector<std::vector<int32_t>> lists(P);
  const auto& bn = s.body_neighbours;
  for (int64_t p = 0; p < P; ++p)
    for (int k = 0; k < bn.k; ++k) {
      const int32_t b = bn.index(p, k);
      if (!bn.valid(p, k) || std::find(lists[p].begin(), lists[p].end(), b) != lists[p].end()) continue;
      lists[p].push_back(b);
      remap[b] = 0;
    }
  const float rb = static_cast<float>(cfg.body_radius);
  for (int64_t p = 0; p < P; ++p)
    if (s.patch_nearest_body.distance[p] < rb) remap[s.patch_nearest_body.index[p]] = 0;
  for (int64_t v = 0; v < N; ++v)
    if (s.vertex_nearest_body.distance[v] < rb) remap[s.vertex_nearest_body.index[v]] = 0;
  std::vector<int32_t> token_vertex;
  for (int64_t b = 0; b < B; ++b)
    if (remap[b] == 0) remap[b] = static_cast<int32_t>(token_vertex.size()), token_vertex.push_back(static_cast<int32_t>(b));
  in.U = static_cast<int64_t>(token_vertex.size());
  in.body_offsets.assign(1, 0);
  for (const auto& l : lists) {
    for (int32_t b : l) in.body_tokens.push_back(remap[b]);
    in.body_offsets.push_back(static_cast<int32_t>(in.body_tokens.size()));
  }
  in.body_norm.resize(in.U * 12);
  in.body_rot.resize(in.U * 9);
  for (int64_t u = 0; u < in.U; ++u) {
    const int32_t b = token_vertex[u];
    for (int c = 0; c < 12; ++c) in.body_norm[12 * u + c] = s.body_state_norm(b, c);
    const double n[3] = {s.body_normals_next(b, 0), s.body_normals_next(b, 1), s.body_normals_next(b, 2)};
    double R[9];
    normal_frame(n, R);
    for (int k = 0; k < 9; ++k) in.body_rot[9 * u + k] = static_cast<float>(R[k]);
  }
  in.patch_body.resize(P);
  in.vertex_body.resize(N);
  for (int64_t p = 0; p < P; ++p)
    in.patch_body[p] = s.patch_nearest_body.distance[p] < rb ? remap[s.patch_nearest_body.index[p]] : -1;
  for (int64_t v = 0; v < N; ++v)
    in.vertex_body[v] = s.vertex_nearest_body.distance[v] < rb ? remap[s.vertex_nearest_body.index[v]] : -1;

  // Wind (t+1, t), gravity and root motion.
  in.has_wind = s.has_wind;
  if (s.has_wind) {
    in.wind = flat(s.wind);
    in.wind_rot.resize(9);
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) in.wind_rot[3 * i + j] = s.wind_rotation[1](i, j);
  }
  if (cfg.wind_force_input && s.has_wind) {
    in.wind_force = wind_force_feature(s);
    const Eigen::Map<const Eigen::Matrix<float, Eigen::Dynamic, 3, Eigen::RowMajor>> force(in.wind_force.data(), N, 3);
    const auto force_patch = dataset::patch_means(st.all, force);
    in.wind_force_patch.assign(force_patch.data(), force_patch.data() + 3 * P);
  }
  in.gravity = flat(s.gravity_norm);
  const auto root = flat(s.root_motion_norm);
  in.gravity.insert(in.gravity.end(), root.begin(), root.end());
  double g_raw[3];  // g/fps − root_acc(t), un-normalised
  for (int c = 0; c < 3; ++c)
    g_raw[c] = s.gravity_norm(1, c) * stats.acceleration.std[c] + stats.acceleration.mean[c];
  double R[9];
  normal_frame(g_raw, R);
  in.gravity_rot.assign(R, R + 9);

  in.mean12.resize(12), in.std12.resize(12);
  for (int c = 0; c < 3; ++c) {
    in.mean12[c] = in.mean12[6 + c] = static_cast<float>(stats.position.mean[c]);
    in.mean12[3 + c] = in.mean12[9 + c] = static_cast<float>(stats.velocity.mean[c]);
    in.std12[c] = in.std12[6 + c] = static_cast<float>(stats.position.std[c]);
    in.std12[3 + c] = in.std12[9 + c] = static_cast<float>(stats.velocity.std[c]);
  }

  // Decoder candidates from x_t and the patch centres.
  std::vector<double> xt(N * 3), centre(P * 3);
  for (int64_t v = 0; v < N; ++v)
    for (int c = 0; c < 3; ++c) xt[3 * v + c] = s.state(v, c);
  for (int64_t p = 0; p < P; ++p)
    for (int c = 0; c < 3; ++c) centre[3 * p + c] = s.patch_state(p, c);
  decoder_candidates(xt, centre, in.own_patch, in.mesh_offsets, in.mesh_senders, cfg.decoder_patch_candidates,
                     in.cand_offsets, in.cand_patches);
  if (cfg.vertex_local_features) {
    const float sigma_v = (in.std12[3] + in.std12[4] + in.std12[5]) / 3.f;
    in.vertex_local = vertex_local_features(s, rb, sigma_v);
  }
  if (cfg.velocity_base != "inertia") {
    const bool relative = cfg.velocity_base == "body_inertia";
    LAYERSNET_CHECK(s.body_carry.rows() == N && (!relative || s.body_carry_prev.rows() == N),
                    "model.velocity_base = \"" << cfg.velocity_base << "\" needs the sample's body_carry"
                                            << (relative ? " and body_carry_prev" : "")
                                            << ": build the sample with sample_options_for(the model's config)");
    if (cfg.velocity_base == "physics") {
      LAYERSNET_CHECK(s.physics_step.rows() == N, "model.velocity_base = \"physics\" needs the sample's physics_step ("
                                                      << s.physics_step.rows() << " rows for " << N
                                                      << " vertices): add it with losses::add_physics_step");
      in.body_carry.assign(s.physics_step.data(), s.physics_step.data() + 3 * N);
      if (cfg.physics_step_correction == "solved") {
        const dataset::BlockSystem<float>& a = s.physics_system;
        LAYERSNET_CHECK(static_cast<int64_t>(a.offsets.size()) == N + 1,
                        "model.physics_step_correction = \"solved\" needs the sample's physics_system ("
                            << a.offsets.size() << " row offsets for " << N
                            << " vertices): add it with losses::add_physics_step");
        in.system_offsets = a.offsets, in.system_columns = a.columns;
        in.system_blocks = a.blocks, in.system_scale = a.scale;
      }
    } else {
      in.body_carry.assign(s.body_carry.data(), s.body_carry.data() + 3 * N);
    }
    if (relative) {  // c + swing_kept (v_t − c_t)
      const float kept = static_cast<float>(cfg.swing_kept);
      for (int64_t v = 0; v < N; ++v)
        for (int c = 0; c < 3; ++c) in.body_carry[3 * v + c] += kept * (s.state(v, 3 + c) - s.body_carry_prev(v, c));
    }
    const Eigen::Map<const Eigen::Matrix<float, Eigen::Dynamic, 3, Eigen::RowMajor>> carry(in.body_carry.data(), N, 3);
    const auto carry_patch = dataset::patch_means(st.all, carry);
    in.body_carry_patch.assign(carry_patch.data(), carry_patch.data() + 3 * P);
  }
  if (cfg.output_smoothing > 0) {
    const auto& nb = s.structure->vertex_neighbours;
    in.vertex_mesh_offsets.assign(1, 0);
    in.vertex_mesh_neighbours.reserve(nb.items.size() + N);
    for (int v = 0; v < static_cast<int>(N); ++v) {
      if (nb.size(v) > 0)
        in.vertex_mesh_neighbours.insert(in.vertex_mesh_neighbours.end(), nb.begin(v), nb.end(v));
      else
        in.vertex_mesh_neighbours.push_back(v);
      in.vertex_mesh_offsets.push_back(static_cast<int32_t>(in.vertex_mesh_neighbours.size()));
    }
  }
  validate(in);
  return in;
}

}  // namespace layersnet::model
