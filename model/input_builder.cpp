#include "model/input_builder.h"

#include "autodiff/check.h"
#include "dataset/neighbours.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <map>
#include <numeric>

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

}  // namespace

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

namespace {

// Root-relative copy of world positions: x - root.
std::vector<double> relative(const std::vector<double>& x, const double root[3]) {
  std::vector<double> r(x.size());
  for (std::size_t i = 0; i < x.size(); ++i) r[i] = x[i] - root[i % 3];
  return r;
}

// Float (P, 3) copy for the data layer's spatial structures (grid, k-d tree).
dataset::Points to_points(const std::vector<double>& x) {
  dataset::Points p(static_cast<Eigen::Index>(x.size() / 3), 3);
  for (std::size_t i = 0; i < x.size(); ++i) p(static_cast<Eigen::Index>(i / 3), static_cast<Eigen::Index>(i % 3)) = static_cast<float>(x[i]);
  return p;
}

// CSR from per-row lists.
void to_csr(const std::vector<std::vector<int32_t>>& rows, std::vector<int32_t>& offsets, std::vector<int32_t>& items) {
  offsets.assign(1, 0);
  items.clear();
  for (const auto& r : rows) {
    items.insert(items.end(), r.begin(), r.end());
    offsets.push_back(static_cast<int32_t>(items.size()));
  }
}

}  // namespace

void quaternion_to_rotation(const double q[4], double R[9]) {
  double w = q[0], x = q[1], y = q[2], z = q[3];
  double n2 = w * w + x * x + y * y + z * z;
  if (n2 < 1e-24) {
    for (int k = 0; k < 9; ++k) R[k] = (k % 4 == 0) ? 1.0 : 0.0;
    return;
  }
  double s = 2.0 / n2;  // scipy normalises the quaternion first
  R[0] = 1 - s * (y * y + z * z), R[1] = s * (x * y - z * w), R[2] = s * (x * z + y * w);
  R[3] = s * (x * y + z * w), R[4] = 1 - s * (x * x + z * z), R[5] = s * (y * z - x * w);
  R[6] = s * (x * z - y * w), R[7] = s * (y * z + x * w), R[8] = 1 - s * (x * x + y * y);
}

std::vector<double> vertex_normals(const std::vector<double>& x, const std::vector<int32_t>& faces) {
  const int64_t V = static_cast<int64_t>(x.size() / 3);
  std::vector<double> n(x.size(), 0.0);
  for (std::size_t f = 0; f + 2 < faces.size(); f += 3) {
    Vec3 a = row3(x, faces[f]), b = row3(x, faces[f + 1]), c = row3(x, faces[f + 2]);
    Vec3 fn = normalized(cross({b[0] - a[0], b[1] - a[1], b[2] - a[2]}, {c[0] - a[0], c[1] - a[1], c[2] - a[2]}));
    for (int k = 0; k < 3; ++k)
      for (int j = 0; j < 3; ++j) n[3 * faces[f + k] + j] += fn[j];
  }
  for (int64_t v = 0; v < V; ++v) {
    Vec3 u = normalized(row3(n, v));
    if (u[0] == 0 && u[1] == 0 && u[2] == 0) u = {0, 0, 1};
    for (int j = 0; j < 3; ++j) n[3 * v + j] = u[j];
  }
  return n;
}

void nearest_points(const std::vector<double>& query, const std::vector<double>& ref, std::vector<int32_t>& index,
                    std::vector<double>& distance) {
  const int64_t Q = static_cast<int64_t>(query.size() / 3), M = static_cast<int64_t>(ref.size() / 3);
  LAYERSNET_CHECK(M > 0, "nearest_points: the reference point set is empty");
  // k-d tree of the data layer (float search); the distance is recomputed in double.
  const auto nn = dataset::nearest_body(to_points(query), to_points(ref));
  index = nn.index;
  distance.assign(Q, 0.0);
  for (int64_t q = 0; q < Q; ++q) distance[q] = std::sqrt(dist2(row3(query, q), row3(ref, index[q])));
}

void decoder_candidates(const std::vector<double>& xt, const std::vector<double>& centre,
                        const std::vector<int32_t>& own_patch, const std::vector<int32_t>& adj_offsets,
                        const std::vector<int32_t>& adj_patches, int k_cand, std::vector<int32_t>& offsets,
                        std::vector<int32_t>& items) {
  const int64_t N = static_cast<int64_t>(own_patch.size());
  std::vector<std::vector<int32_t>> cand(N);
  for (int64_t v = 0; v < N; ++v) {
    const int32_t own = own_patch[v];
    if (own < 0) continue;
    std::vector<std::pair<double, int32_t>> c;
    for (int32_t k = adj_offsets[own]; k < adj_offsets[own + 1]; ++k) {
      const int32_t p = adj_patches[k];
      c.emplace_back(std::sqrt(dist2(row3(xt, v), row3(centre, p))), p);
    }
    const std::size_t kk = std::min<std::size_t>(c.size(), static_cast<std::size_t>(k_cand));
    std::partial_sort(c.begin(), c.begin() + kk, c.end());
    for (std::size_t j = 0; j < kk; ++j) {
      const int32_t p = c[j].second;
      const double pd = std::sqrt(dist2(row3(centre, own), row3(centre, p)));
      if (p == own || pd == 0 || c[j].first < pd) cand[v].push_back(p);
    }
  }
  to_csr(cand, offsets, items);
}

ModelInput<double> build_model_input(const SceneWindow& s, const ModelConfig& cfg) {
  const int64_t N = s.N, P = s.P, B = s.B;
  LAYERSNET_CHECK(static_cast<int64_t>(s.x_t.size()) == 3 * N && s.x_tm1.size() == s.x_t.size() &&
                      s.x_tm2.size() == s.x_t.size(),
                  "SceneWindow: x_tm2, x_tm1, x_t must be (N, 3) with N = " << N);
  LAYERSNET_CHECK(static_cast<int64_t>(s.body_tp1.size()) == 3 * B && s.body_t.size() == s.body_tp1.size() &&
                      s.body_tm1.size() == s.body_tp1.size() && B > 0,
                  "SceneWindow: body_tm1, body_t, body_tp1 must be (B, 3) with B = " << B << " > 0");
  LAYERSNET_CHECK(static_cast<int64_t>(s.p2v_offsets.size()) == P + 1 &&
                      static_cast<int64_t>(s.v2p_offsets.size()) == N + 1 &&
                      static_cast<int64_t>(s.adj_offsets.size()) == P + 1,
                  "SceneWindow: v2p (N+1), p2v and adjacency (P+1) offsets have wrong sizes");
  ModelInput<double> in;
  in.N = N, in.P = P;

  // ---- root-relative states ------------------------------------------------------------------
  const auto xt = relative(s.x_t, s.root[2]), xm1 = relative(s.x_tm1, s.root[1]), xm2 = relative(s.x_tm2, s.root[0]);
  in.state.resize(N * 12);
  for (int64_t v = 0; v < N; ++v)
    for (int c = 0; c < 3; ++c) {
      double* r = &in.state[12 * v];
      r[c] = xt[3 * v + c];
      r[3 + c] = xt[3 * v + c] - xm1[3 * v + c];
      r[6 + c] = xm1[3 * v + c];
      r[9 + c] = xm1[3 * v + c] - xm2[3 * v + c];
    }
  in.mean12.resize(12);
  in.std12.resize(12);
  for (int c = 0; c < 3; ++c) {
    in.mean12[c] = in.mean12[6 + c] = s.stats.pos_mean[c];
    in.mean12[3 + c] = in.mean12[9 + c] = s.stats.vel_mean[c];
    in.std12[c] = in.std12[6 + c] = s.stats.pos_std[c] == 0 ? 1.0 : s.stats.pos_std[c];
    in.std12[3 + c] = in.std12[9 + c] = s.stats.vel_std[c] == 0 ? 1.0 : s.stats.vel_std[c];
  }
  auto normalise = [&](std::vector<double> x) {
    for (std::size_t i = 0; i < x.size(); ++i) x[i] = (x[i] - in.mean12[i % 12]) / in.std12[i % 12];
    return x;
  };
  in.state_norm = normalise(in.state);

  // ---- patches ---------------------------------------------------------------------------------
  in.v2p_offsets = s.v2p_offsets, in.v2p_patches = s.v2p_patches, in.own_patch = s.own_patch;
  in.p2v_offsets = s.p2v_offsets, in.p2v_vertices = s.p2v_vertices;
  in.mesh_offsets = s.adj_offsets, in.mesh_senders = s.adj_patches;
  in.patch_state.assign(P * 12, 0.0);
  for (int64_t p = 0; p < P; ++p) {
    const int32_t b = s.p2v_offsets[p], e = s.p2v_offsets[p + 1];
    LAYERSNET_CHECK(e > b, "SceneWindow: patch " << p << " has no member vertex; drop empty patches");
    for (int32_t k = b; k < e; ++k)
      for (int c = 0; c < 12; ++c) in.patch_state[12 * p + c] += in.state[12 * s.p2v_vertices[k] + c];
    for (int c = 0; c < 12; ++c) in.patch_state[12 * p + c] /= (e - b);
  }
  in.patch_norm = normalise(in.patch_state);
  std::vector<double> centre(P * 3);
  for (int64_t p = 0; p < P; ++p)
    for (int c = 0; c < 3; ++c) centre[3 * p + c] = in.patch_state[12 * p + c];

  // ---- attribute tokens (identical attribute vectors share one token) ------------------------------
  const int64_t G = static_cast<int64_t>(s.garment_offsets.size()) - 1;
  std::map<std::vector<double>, int32_t> attr_id;
  std::vector<int32_t> garment_token(G);
  for (int64_t g = 0; g < G; ++g) {
    std::vector<double> a(s.garment_attr.begin() + 5 * g, s.garment_attr.begin() + 5 * g + 5);
    auto [it, fresh] = attr_id.emplace(a, static_cast<int32_t>(attr_id.size()));
    if (fresh) in.attr.insert(in.attr.end(), a.begin(), a.end());
    garment_token[g] = it->second;
  }
  in.A = static_cast<int64_t>(attr_id.size());
  in.patch_attr.resize(P);
  for (int64_t p = 0; p < P; ++p) in.patch_attr[p] = garment_token[s.patch_garment[p]];

  // ---- world edges (hash grid of the data layer, cell = R) ------------------------------------------
  const auto centre_pts = to_points(centre);
  dataset::Csr adjacency;
  adjacency.offsets = s.adj_offsets;
  adjacency.items = s.adj_patches;
  for (int64_t p = 0; p < P; ++p)  // world_edges binary-searches the adjacency rows
    std::sort(adjacency.items.begin() + adjacency.offsets[p], adjacency.items.begin() + adjacency.offsets[p + 1]);
  {
    const auto w = dataset::world_edges(centre_pts, adjacency, static_cast<float>(cfg.world_radius));
    in.world_offsets = w.offsets, in.world_senders = w.items;
  }

  // ---- body: root-relative states, neighbours, nearest -----------------------------------------------
  const auto b1 = relative(s.body_tp1, s.root[3]), b0 = relative(s.body_t, s.root[2]),
             bm = relative(s.body_tm1, s.root[1]);
  const bool first_k = cfg.body_query == "first";
  LAYERSNET_CHECK(first_k || cfg.body_query == "nearest",
                  "model.body_query = '" << cfg.body_query << "': use \"nearest\" or \"first\"");
  const auto b1_pts = to_points(b1);
  std::vector<std::vector<int32_t>> body_nb(P);
  {
    dataset::NeighbourOptions o;
    o.body_radius = static_cast<float>(cfg.body_radius);
    o.body_k = cfg.body_neighbors;
    o.body_query = first_k ? dataset::BodyQuery::kFirstInIndexOrder : dataset::BodyQuery::kNearest;
    o.official_padding = false;  // unfilled slots are absent (README quirk 3)
    const auto nb = dataset::body_neighbours(centre_pts, b1_pts, o);
    for (int64_t p = 0; p < P; ++p)
      for (int32_t k = 0; k < nb.hits[p]; ++k) body_nb[p].push_back(nb.index(p, k));
  }
  std::vector<int32_t> p_nn, v_nn;
  std::vector<double> p_nn_d, v_nn_d;
  nearest_points(centre, b1, p_nn, p_nn_d);
  nearest_points(xt, b1, v_nn, v_nn_d);
  // Body tokens: every referenced body vertex once, in ascending vertex order.
  std::vector<int32_t> remap(B, -1);
  for (const auto& r : body_nb)
    for (int32_t b : r) remap[b] = 0;
  for (int64_t p = 0; p < P; ++p)
    if (p_nn_d[p] < cfg.body_radius) remap[p_nn[p]] = 0;
  for (int64_t v = 0; v < N; ++v)
    if (v_nn_d[v] < cfg.body_radius) remap[v_nn[v]] = 0;
  std::vector<int32_t> token_vertex;
  for (int64_t b = 0; b < B; ++b)
    if (remap[b] == 0) remap[b] = static_cast<int32_t>(token_vertex.size()), token_vertex.push_back(static_cast<int32_t>(b));
  in.U = static_cast<int64_t>(token_vertex.size());
  for (auto& r : body_nb)
    for (int32_t& b : r) b = remap[b];
  to_csr(body_nb, in.body_offsets, in.body_tokens);
  in.patch_body.resize(P);
  in.vertex_body.resize(N);
  for (int64_t p = 0; p < P; ++p) in.patch_body[p] = p_nn_d[p] < cfg.body_radius ? remap[p_nn[p]] : -1;
  for (int64_t v = 0; v < N; ++v) in.vertex_body[v] = v_nn_d[v] < cfg.body_radius ? remap[v_nn[v]] : -1;
  dataset::Faces body_faces(static_cast<Eigen::Index>(s.body_faces.size() / 3), 3);
  for (std::size_t i = 0; i < s.body_faces.size(); ++i)
    body_faces(static_cast<Eigen::Index>(i / 3), static_cast<Eigen::Index>(i % 3)) = s.body_faces[i];
  const dataset::Points body_n = dataset::vertex_normals(b1_pts, body_faces);  // same as the dataset path
  in.body_norm.resize(in.U * 12);
  in.body_rot.resize(in.U * 9);
  for (int64_t u = 0; u < in.U; ++u) {
    const int32_t b = token_vertex[u];
    double* r = &in.body_norm[12 * u];
    for (int c = 0; c < 3; ++c) {
      r[c] = b1[3 * b + c];
      r[3 + c] = b1[3 * b + c] - b0[3 * b + c];
      r[6 + c] = b0[3 * b + c];
      r[9 + c] = b0[3 * b + c] - bm[3 * b + c];
    }
    for (int c = 0; c < 12; ++c) r[c] = (r[c] - in.mean12[c]) / in.std12[c];
    const double nb[3] = {body_n(b, 0), body_n(b, 1), body_n(b, 2)};
    normal_frame(nb, &in.body_rot[9 * u]);
  }

  // ---- wind and gravity ----------------------------------------------------------------------------------
  in.has_wind = s.has_wind;
  if (s.has_wind) {
    in.wind.assign(s.wind_tp1, s.wind_tp1 + 5);
    in.wind.insert(in.wind.end(), s.wind_t, s.wind_t + 5);
    in.wind_rot.resize(9);
    quaternion_to_rotation(s.wind_t, in.wind_rot.data());
  }
  double rv[2][3], ra[2][3], g_raw_t[3];  // [0] = t+1, [1] = t
  for (int c = 0; c < 3; ++c) {
    rv[0][c] = s.root[3][c] - s.root[2][c];
    rv[1][c] = s.root[2][c] - s.root[1][c];
    ra[0][c] = rv[0][c] - rv[1][c];
    ra[1][c] = rv[1][c] - (s.root[1][c] - s.root[0][c]);
    g_raw_t[c] = s.gravity[c] / s.fps - ra[1][c];
  }
  const auto& st = s.stats;
  in.gravity.resize(18);
  for (int f = 0; f < 2; ++f)
    for (int c = 0; c < 3; ++c) {
      in.gravity[3 * f + c] = (s.gravity[c] / s.fps - ra[f][c] - st.acc_mean[c]) / st.acc_std[c];
      in.gravity[6 + 6 * f + c] = (rv[f][c] - st.root_vel_mean[c]) / st.root_vel_std[c];
      in.gravity[9 + 6 * f + c] = (ra[f][c] - st.root_acc_mean[c]) / st.root_acc_std[c];
    }
  in.gravity_rot.resize(9);
  normal_frame(g_raw_t, in.gravity_rot.data());

  // ---- decoder candidates -----------------------------------------------------------------------------------
  decoder_candidates(xt, centre, s.own_patch, s.adj_offsets, s.adj_patches, cfg.decoder_patch_candidates,
                     in.cand_offsets, in.cand_patches);
  validate(in);
  return in;
}

}  // namespace layersnet::model
