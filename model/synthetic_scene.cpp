#include "model/synthetic_scene.h"

#include "autodiff/check.h"

#include <algorithm>
#include <cmath>
#include <random>
#include <set>

namespace layersnet::model {
namespace {

// Triangulated grid (nu x nv vertices, vertex (i, j) -> off + i*nv + j); `wrap` closes it
// around i. Also returns the quad (i, j) of every face.
void grid_faces(int nu, int nv, int off, bool wrap, std::vector<int32_t>& faces, std::vector<std::array<int, 2>>* quads) {
  const int iu = wrap ? nu : nu - 1;
  for (int i = 0; i < iu; ++i)
    for (int j = 0; j + 1 < nv; ++j) {
      const int i1 = (i + 1) % nu;
      const int a = off + i * nv + j, b = off + i1 * nv + j, c = off + i1 * nv + j + 1, d = off + i * nv + j + 1;
      faces.insert(faces.end(), {a, b, c, a, c, d});
      if (quads) quads->push_back({i, j}), quads->push_back({i, j});
    }
}

}  // namespace

SceneWindow make_synthetic_scene(const SyntheticSceneOptions& o) {
  LAYERSNET_CHECK(!o.garments.empty(), "SyntheticSceneOptions.garments is empty: give at least one garment grid");
  std::mt19937_64 rng(o.seed);
  std::normal_distribution<double> noise(0.0, 1.0);
  std::uniform_real_distribution<double> uni(0.0, 1.0);
  SceneWindow s;
  const double pi = 3.14159265358979323846;

  // ---- garments: rest shape, faces, patches -------------------------------------------------------
  std::vector<double> rest;
  std::vector<std::set<int32_t>> v2p;
  std::vector<int32_t> patch_garment;
  s.garment_offsets.push_back(0);
  int32_t p_base = 0;
  for (std::size_t gi = 0; gi < o.garments.size(); ++gi) {
    const int nu = o.garments[gi][0], nv = o.garments[gi][1];
    const double r_nom = gi < o.garment_radius.size() ? o.garment_radius[gi] : 1.05 + 0.05 * static_cast<double>(gi);
    const double z0 = gi < o.garment_z0.size() ? o.garment_z0[gi] : -0.05 * static_cast<double>(gi);
    const int off = s.garment_offsets.back();
    for (int i = 0; i < nu; ++i)
      for (int j = 0; j < nv; ++j) {
        const double th = i * o.spacing / r_nom, z = z0 + j * o.spacing;
        const double rr = r_nom + 0.03 * std::sin(5 * th + 0.5 + static_cast<double>(gi)) * std::sin(4 * z + 0.3);
        rest.insert(rest.end(), {rr * std::cos(th), rr * std::sin(th), z});
      }
    std::vector<std::array<int, 2>> quads;
    const std::size_t f0 = s.faces.size() / 3;
    grid_faces(nu, nv, off, false, s.faces, &quads);
    v2p.resize(off + nu * nv);
    // Official patchwise: the face's cell; cells numbered densely in (u-cell, v-cell) order.
    std::set<std::array<int, 2>> cells;
    for (const auto& q : quads) cells.insert({q[0] / o.cell[0], q[1] / o.cell[1]});
    std::vector<std::array<int, 2>> cell_list(cells.begin(), cells.end());
    for (std::size_t f = 0; f < quads.size(); ++f) {
      const std::array<int, 2> c{quads[f][0] / o.cell[0], quads[f][1] / o.cell[1]};
      const int32_t pid =
          p_base + static_cast<int32_t>(std::lower_bound(cell_list.begin(), cell_list.end(), c) - cell_list.begin());
      for (int k = 0; k < 3; ++k) v2p[s.faces[3 * (f0 + f) + k]].insert(pid);
    }
    for (std::size_t c = 0; c < cell_list.size(); ++c) patch_garment.push_back(static_cast<int32_t>(gi));
    p_base += static_cast<int32_t>(cell_list.size());
    s.garment_offsets.push_back(off + nu * nv);
  }
  s.N = s.garment_offsets.back();
  s.P = p_base;
  s.patch_garment = patch_garment;
  std::vector<std::vector<int32_t>> p2v(s.P);
  s.v2p_offsets.push_back(0);
  for (int64_t v = 0; v < s.N; ++v) {
    for (int32_t p : v2p[v]) s.v2p_patches.push_back(p), p2v[p].push_back(static_cast<int32_t>(v));
    s.v2p_offsets.push_back(static_cast<int32_t>(s.v2p_patches.size()));
    s.own_patch.push_back(v2p[v].empty() ? -1 : *v2p[v].begin());
  }
  s.p2v_offsets.push_back(0);
  for (const auto& r : p2v) {
    s.p2v_vertices.insert(s.p2v_vertices.end(), r.begin(), r.end());
    s.p2v_offsets.push_back(static_cast<int32_t>(s.p2v_vertices.size()));
  }
  // Mesh adjacency: every mesh edge (u, v) joins P(u) x P(v) both ways (self pairs included).
  std::vector<std::set<int32_t>> adj(s.P);
  for (std::size_t f = 0; f < s.faces.size(); f += 3)
    for (int k = 0; k < 3; ++k) {
      const int32_t u = s.faces[f + k], w = s.faces[f + (k + 1) % 3];
      for (int32_t pu : v2p[u])
        for (int32_t pw : v2p[w]) adj[pu].insert(pw), adj[pw].insert(pu);
    }
  s.adj_offsets.push_back(0);
  for (const auto& r : adj) {
    s.adj_patches.insert(s.adj_patches.end(), r.begin(), r.end());
    s.adj_offsets.push_back(static_cast<int32_t>(s.adj_patches.size()));
  }
  for (std::size_t g = 0; g < o.garments.size(); ++g)
    for (int k = 0; k < 5; ++k) s.garment_attr.push_back(uni(rng));

  // ---- body: closed bumpy cylinder ---------------------------------------------------------------------
  const int nth = o.body[0], nz = o.body[1];
  std::vector<double> body_rest;
  for (int i = 0; i < nth; ++i)
    for (int j = 0; j < nz; ++j) {
      const double th = 2 * pi * i / nth, z = o.body_z[0] + (o.body_z[1] - o.body_z[0]) * j / std::max(1, nz - 1);
      const double rb = o.body_radius + 0.02 * std::sin(3 * th) * std::cos(2 * z);
      body_rest.insert(body_rest.end(), {rb * std::cos(th), rb * std::sin(th), z});
    }
  grid_faces(nth, nz, 0, true, s.body_faces, nullptr);
  s.B = nth * nz;

  // ---- motion: root-relative positions at t-2..t+1 from smooth fields + noise ------------------------------
  auto field = [](double x, double y, double z, double amp, double ph, double out[3]) {
    const double th = std::atan2(y, x);
    out[0] = amp * std::sin(z + th + ph), out[1] = amp * std::cos(0.7 * z + ph), out[2] = amp * 0.5 * std::sin(th - ph);
  };
  auto frames = [&](const std::vector<double>& x0, double vamp, double aamp, double nz_amp, std::vector<double>* out[4]) {
    const std::size_t n = x0.size() / 3;
    for (int f = 0; f < 4; ++f) out[f]->resize(x0.size());
    for (std::size_t i = 0; i < n; ++i) {
      double xt[3], v[3], a0[3], a1[3];
      for (int c = 0; c < 3; ++c) xt[c] = x0[3 * i + c] + nz_amp * noise(rng);
      field(xt[0], xt[1], xt[2], vamp, 0.0, v);
      field(xt[0], xt[1], xt[2], aamp, 1.0, a0);
      field(xt[0], xt[1], xt[2], aamp, 2.0, a1);
      for (int c = 0; c < 3; ++c) {
        const double vt = v[c] + 0.1 * vamp * noise(rng), vm1 = vt - a0[c];
        (*out[2])[3 * i + c] = xt[c];
        (*out[1])[3 * i + c] = xt[c] - vt;
        (*out[0])[3 * i + c] = xt[c] - vt - vm1;
        (*out[3])[3 * i + c] = xt[c] + vt + a1[c];
      }
    }
  };
  std::vector<double>* g_out[4] = {&s.x_tm2, &s.x_tm1, &s.x_t, &s.x_tp1};
  frames(rest, 0.02, 0.004, 0.002, g_out);
  std::vector<double> body_tm2;
  std::vector<double>* b_out[4] = {&body_tm2, &s.body_tm1, &s.body_t, &s.body_tp1};
  frames(body_rest, 0.01, 0.002, 0.001, b_out);

  // Statistics on the root-relative scene (before the root is added).
  auto stats3 = [](const std::vector<double>& a, const std::vector<double>& b, double mean[3], double sd[3]) {
    for (int c = 0; c < 3; ++c) {
      double s1 = 0, s2 = 0, n = 0;
      for (const auto* v : {&a, &b})
        for (std::size_t i = c; i < v->size(); i += 3) s1 += (*v)[i], s2 += (*v)[i] * (*v)[i], n += 1;
      mean[c] = s1 / n;
      sd[c] = std::sqrt(std::max(s2 / n - mean[c] * mean[c], 1e-12));
    }
  };
  std::vector<double> gv(s.x_t.size()), bv(s.body_tp1.size()), ga(s.x_t.size());
  for (std::size_t i = 0; i < gv.size(); ++i) gv[i] = s.x_t[i] - s.x_tm1[i], ga[i] = gv[i] - (s.x_tm1[i] - s.x_tm2[i]);
  for (std::size_t i = 0; i < bv.size(); ++i) bv[i] = s.body_tp1[i] - s.body_t[i];
  stats3(s.x_t, s.body_tp1, s.stats.pos_mean, s.stats.pos_std);
  stats3(gv, bv, s.stats.vel_mean, s.stats.vel_std);
  stats3(ga, ga, s.stats.acc_mean, s.stats.acc_std);
  for (int c = 0; c < 3; ++c) s.stats.root_vel_std[c] = 0.05, s.stats.root_acc_std[c] = 0.01;

  // ---- root motion, then everything to world coordinates ------------------------------------------------------
  for (int f = 0; f < 4; ++f) {
    const double k = f - 2.0;  // frame relative to t
    s.root[f][0] = o.root_offset[0] + 0.03 * k + 0.004 * k * k;
    s.root[f][1] = o.root_offset[1] - 0.02 * k;
    s.root[f][2] = o.root_offset[2] + 0.003 * k * k;
  }
  auto to_world = [](std::vector<double>& x, const double r[3]) {
    for (std::size_t i = 0; i < x.size(); ++i) x[i] += r[i % 3];
  };
  to_world(s.x_tm2, s.root[0]), to_world(s.x_tm1, s.root[1]), to_world(s.x_t, s.root[2]), to_world(s.x_tp1, s.root[3]);
  to_world(s.body_tm1, s.root[1]), to_world(s.body_t, s.root[2]), to_world(s.body_tp1, s.root[3]);

  s.has_wind = o.wind;
  if (o.wind) {
    double q[4], n = 0;
    for (double& x : q) x = noise(rng), n += x * x;
    for (double& x : q) x /= std::sqrt(n);
    const double strength = uni(rng);
    std::copy(q, q + 4, s.wind_t), std::copy(q, q + 4, s.wind_tp1);
    s.wind_t[4] = s.wind_tp1[4] = strength;
  }
  return s;
}

}  // namespace layersnet::model
