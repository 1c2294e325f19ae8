#include "model/sample_input.h"

#include "autodiff/check.h"
#include "model/input_builder.h"

#include <algorithm>

namespace layersnet::model {
namespace {

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

}  // namespace

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
  validate(in);
  return in;
}

}  // namespace layersnet::model
