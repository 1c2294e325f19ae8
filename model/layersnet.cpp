#include "model/layersnet.h"

#include "autodiff/ops_attention.h"
#include "autodiff/ops_solve.h"

#include "model/params_layout.h"
#include "model/tape_helpers.h"

#include <array>
#include <chrono>
#include <cmath>
#include <vector>

namespace layersnet::model {
namespace {

constexpr double kEps = 1e-7;  // official eps of the attention denominators

// Adds the wall time from construction to stop() (or destruction) to one StageTimes field;
// with no StageTimes it never reads the clock.
class StageClock {
 public:
  StageClock(StageTimes* times, double StageTimes::*field) : sink_(times ? &(times->*field) : nullptr) {
    if (sink_) t0_ = std::chrono::steady_clock::now();
  }
  ~StageClock() { stop(); }
  StageClock(const StageClock&) = delete;
  StageClock& operator=(const StageClock&) = delete;
  void stop() {
    if (!sink_) return;
    *sink_ += std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0_).count();
    sink_ = nullptr;
  }

 private:
  double* sink_;
  std::chrono::steady_clock::time_point t0_;
};

// Edge kinds of the fused attention and the heads that attend to them (as the official
// code): world heads [0, G) attend world-neighbour patches and, in the same softmax, the
// body/wind/gravity tokens (inter edges); mesh heads [G, 2G) attend mesh-adjacent patches
// and the garment's attribute token. Inter edges send their messages through the RET, so
// only world and mesh edges add the fused (s + r) message.
enum EdgeKind : int32_t { kWorldEdge = 0, kMeshEdge = 1, kInterEdge = 2 };
constexpr uint32_t kSelfMessageKinds = (1u << kWorldEdge) | (1u << kMeshEdge);

std::vector<uint32_t> head_kinds(int64_t groups) {
  std::vector<uint32_t> table;
  for (int64_t h = 0; h < 2 * groups; ++h)
    table.push_back(h < groups ? (1u << kWorldEdge) | (1u << kInterEdge) : (1u << kMeshEdge));
  return table;
}

// Index lists of one forward (built from ModelInput, no tape). Token table rows:
//   [0, P) patches, [P, P+A) attribute tokens, [P+A, P+A+T) body/wind/gravity tokens.
template <class T>
struct Graph {
  int64_t P = 0, A = 0, T_rows = 0;
  // World heads: world edges and inter edges of each receiver, one joint CSR (world first).
  std::vector<int32_t> joint_offsets, joint_recv, joint_send;
  std::vector<T> joint_is_world;  // (Ej, 1): 1 for a world edge, 0 for an inter edge
  std::vector<int32_t> inter_pos, inter_offsets;  // positions of inter edges in the joint list; their CSR over P
  std::vector<T> inter_rot;                       // (Ei, 9) frame of each inter edge's token
  // Mesh heads: mesh adjacency + own attribute token.
  std::vector<int32_t> mesh_offsets, mesh_recv, mesh_send;
  // The fused op's single list: per receiver world, inter, mesh edges with their kinds.
  std::vector<int32_t> fused_offsets, fused_send, fused_kind, fused_inter_pos, inter_recv, inter_send;
  std::vector<uint32_t> head_kinds;  // heads [0, G): world + inter; [G, 2G): mesh
};

template <class T>
Graph<T> build_graph(const ModelInput<T>& in, int64_t groups) {
  Graph<T> g;
  g.head_kinds = head_kinds(groups);
  const int64_t P = in.P;
  g.P = P, g.A = in.A;
  const int64_t U = in.U, wind_tok = in.has_wind ? U : -1, grav_tok = U + (in.has_wind ? 1 : 0);
  g.T_rows = grav_tok + 1;
  const int32_t tok0 = static_cast<int32_t>(P + in.A);
  static const T kIdentity[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};
  g.joint_offsets.push_back(0);
  g.inter_offsets.push_back(0);
  g.mesh_offsets.push_back(0);
  for (int64_t i = 0; i < P; ++i) {
    const int32_t ri = static_cast<int32_t>(i);
    for (int32_t k = in.world_offsets[i]; k < in.world_offsets[i + 1]; ++k) {
      g.joint_recv.push_back(ri), g.joint_send.push_back(in.world_senders[k]), g.joint_is_world.push_back(T(1));
    }
    auto add_inter = [&](int64_t token, const T* rot) {
      g.inter_pos.push_back(static_cast<int32_t>(g.joint_recv.size()));
      g.joint_recv.push_back(ri), g.joint_send.push_back(tok0 + static_cast<int32_t>(token));
      g.joint_is_world.push_back(T(0));
      g.inter_rot.insert(g.inter_rot.end(), rot, rot + 9);
    };
    for (int32_t k = in.body_offsets[i]; k < in.body_offsets[i + 1]; ++k)
      add_inter(in.body_tokens[k], in.body_rot.empty() ? kIdentity : &in.body_rot[9 * in.body_tokens[k]]);
    if (wind_tok >= 0) add_inter(wind_tok, in.wind_rot.data());
    add_inter(grav_tok, in.gravity_rot.data());
    g.joint_offsets.push_back(static_cast<int32_t>(g.joint_recv.size()));
    g.inter_offsets.push_back(static_cast<int32_t>(g.inter_pos.size()));
    for (int32_t k = in.mesh_offsets[i]; k < in.mesh_offsets[i + 1]; ++k)
      g.mesh_recv.push_back(ri), g.mesh_send.push_back(in.mesh_senders[k]);
    g.mesh_recv.push_back(ri), g.mesh_send.push_back(static_cast<int32_t>(P + in.patch_attr[i]));
    g.mesh_offsets.push_back(static_cast<int32_t>(g.mesh_recv.size()));
  }
  // Fused list from the two above.
  g.fused_offsets.push_back(0);
  for (int64_t i = 0; i < P; ++i) {
    for (int32_t k = g.joint_offsets[i]; k < g.joint_offsets[i + 1]; ++k) {
      const bool world = g.joint_is_world[k] != T(0);
      if (!world) {
        g.fused_inter_pos.push_back(static_cast<int32_t>(g.fused_send.size()));
        g.inter_recv.push_back(static_cast<int32_t>(i)), g.inter_send.push_back(g.joint_send[k]);
      }
      g.fused_send.push_back(g.joint_send[k]), g.fused_kind.push_back(world ? kWorldEdge : kInterEdge);
    }
    for (int32_t k = g.mesh_offsets[i]; k < g.mesh_offsets[i + 1]; ++k)
      g.fused_send.push_back(g.mesh_send[k]), g.fused_kind.push_back(kMeshEdge);
    g.fused_offsets.push_back(static_cast<int32_t>(g.fused_send.size()));
  }
  return g;
}

template <class T>
struct Streams {
  Var<T> X;  // (P + A + T, d) token states: patches, then attribute and body/wind/gravity tokens
  Var<T> R;  // (P, d) receiver memory
  Var<T> S;  // (P + A + T, d) sender memory
};

// Attention logits and normalised edge vectors of one head family.
//   RIA (eq. 7, official form): logit = scale (q·s + q·r) / (‖r−s‖/2 + eps), weight a/(‖r−s‖ + eps),
//                               edge vector f = r + s.
//   TIE (official attention.py): f = LayerNorm_per_head(r + s) (no affine), logit = scale q·f, weight a.
template <class T>
struct EdgeTerms {
  Var<T> logits, inv_norm, f;  // (E, G), (E, G) or empty (TIE), (E, G*hd)
};

template <class T>
EdgeTerms<T> edge_terms(ad::Tape<T>& tape, const ModelConfig& cfg, const ModelDims& m, const Var<T>& q,
                        const Var<T>& r, const Var<T>& s, std::span<const int32_t> recv, std::span<const int32_t> send) {
  const int64_t G = m.groups, E = static_cast<int64_t>(recv.size());
  const T scale = static_cast<T>(1.0 / std::sqrt(static_cast<double>(m.head_dim)));
  const Var<T> re = ad::gather_rows(tape, r, recv), se = ad::gather_rows(tape, s, send);
  const Var<T> qe = ad::gather_rows(tape, q, recv);
  const T eps_v = static_cast<T>(kEps);
  const Var<T> eps = tape.constant(&eps_v, 1, 1);
  EdgeTerms<T> out;
  if (cfg.attention == "tie") {
    const Var<T> e = ad::add(tape, re, se);
    out.f = view(ad::layer_norm(tape, view(e, E * G, m.head_dim), Var<T>{}, Var<T>{}), E, G * m.head_dim);
    out.logits = ad::scale(tape, head_dot(tape, qe, out.f, G), scale);
    return out;
  }
  const Var<T> dist = head_norm(tape, ad::sub(tape, re, se), G);                          // ‖r − s‖ per head
  const Var<T> qsr = head_dot(tape, qe, ad::add(tape, se, re), G);                         // q·s + q·r
  const Var<T> den = ad::add(tape, ad::scale(tape, dist, T(0.5)), eps);
  out.logits = ad::scale(tape, ad::div(tape, qsr, den), scale);
  out.inv_norm = ad::add(tape, dist, eps);
  out.f = ad::add(tape, re, se);
  return out;
}

// Message weights a (softmax) -> per-edge weights (a / (‖r−s‖ + eps) for RIA, a for TIE).
template <class T>
Var<T> edge_weights(ad::Tape<T>& tape, const EdgeTerms<T>& t, std::span<const int32_t> offsets) {
  const Var<T> a = ad::segment_softmax(tape, t.logits, offsets);
  return t.inv_norm.value ? ad::div(tape, a, t.inv_norm) : a;
}

// xᵀ for a small matrix x (r, c) -> (c, r), on the tape: x applied to the identity.
template <class T>
Var<T> transpose_of(ad::Tape<T>& tape, const Var<T>& x) {
  std::vector<T> eye(x.cols * x.cols, T(0));
  for (int64_t i = 0; i < x.cols; ++i) eye[i * x.cols + i] = T(1);
  return ad::linear(tape, constant(tape, eye, x.cols, x.cols), x);  // I xᵀ
}

template <class T>
Var<T> rotation_map_impl(ad::Tape<T>& tape, const ParamView<T>& p, const ModelConfig& cfg, const std::string& name) {
  const Var<T> V = p(name);  // (d, c), c = 3 or 3k
  if (cfg.orthogonality != "exact") return V;
  const Var<T> Vt = transpose_of(tape, V);  // (c, d): columns as rows
  auto minus_proj = [&](const Var<T>& x, const Var<T>& u) {  // x − (x·u) u, u unit
    return ad::sub(tape, x, ad::mul(tape, u, ad::row_sum(tape, ad::mul(tape, x, u))));
  };
  Var<T> Ut;  // Gram–Schmidt of the rows, (c, d)
  std::vector<Var<T>> us;
  for (int64_t i = 0; i < Vt.rows; ++i) {
    Var<T> r = rows_of(Vt, i, i + 1);
    for (const Var<T>& u : us) r = minus_proj(r, u);
    us.push_back(ad::row_normalize(tape, r));
    Ut = i == 0 ? us.back() : ad::concat_rows(tape, Ut, us.back());
  }
  return transpose_of(tape, Ut);  // (d, c)
}

// ψ with RET for the inter edges of group g: φ(R)ᵀ ReLU(A_g φ(R) v + c_g), φ(R) = W_g R W_gᵀ (eq. 10–11).
// group_input(g) gives v's columns of group g, (E, head_dim).
template <class T, class GroupInput>
Var<T> inter_messages(ad::Tape<T>& tape, const ParamView<T>& p, const ModelConfig& cfg, const ModelDims& m,
                      const std::string& prefix, GroupInput&& group_input, const Var<T>& rot) {
  std::vector<Var<T>> parts;
  for (int g = 0; g < m.groups; ++g) {
    const std::string gs = std::to_string(g);
    Var<T> y = group_input(g);
    Var<T> W;
    if (cfg.rotation_equivalent) {
      W = rotation_map_impl(tape, p, cfg, prefix + "rot_mapping." + gs + ".weight");
      y = ad::rot_map_apply(tape, W, rot, y);
    }
    y = ad::linear_relu(tape, y, p(prefix + "rs_mlp." + gs + ".weight"), p(prefix + "rs_mlp." + gs + ".bias"));
    if (cfg.rotation_equivalent) y = ad::rot_map_apply(tape, W, rot, y, /*transpose=*/true);
    parts.push_back(y);
  }
  return ad::concat_cols(tape, std::span<const Var<T>>(parts));
}

// One simulator layer (official post-LN encoder layer, with the decisions of model/README.md).
template <class T>
Streams<T> encoder_layer(ad::Tape<T>& tape, const ParamView<T>& p, const ModelConfig& cfg, const ModelDims& m,
                         const Graph<T>& gr, const Var<T>& inter_rot, const Var<T>& is_world, int layer,
                         const Streams<T>& st, const ForwardOptions& opt) {
  const std::string pre = "encoder.layers." + std::to_string(layer) + ".";
  const std::string at = pre + "attn.";
  const bool last = layer == m.layers - 1;
  const int64_t P = gr.P, d = m.d, half = d / 2, G = m.groups;
  const Var<T> Xp = rows_of(st.X, 0, P);
  StageClock attention_clock(opt.times, &StageTimes::attention_ms);
  // r = W_r x + W_m R + R;  s = W_s x + W_m S + S (every token);  q = W_q x.
  const Var<T> Wm = p(at + "memory_weight.weight");
  const Var<T> r = ad::linear_add(tape, st.R, Wm, {}, ad::linear_add(tape, Xp, p(at + "receiver_weight.weight"), {}, st.R));
  const Var<T> s = ad::linear_add(tape, st.S, Wm, {}, ad::linear_add(tape, st.X, p(at + "sender_weight.weight"), {}, st.S));
  const Var<T> q = ad::linear(tape, Xp, p(at + "q_proj.weight"));
  Var<T> out;
  StageClock edges_clock(opt.times, &StageTimes::attention_edges_ms);
  if (cfg.attention == "ria" && opt.fused_attention) {
    const ad::RiaGraph graph{gr.fused_offsets, gr.fused_send, gr.fused_kind, gr.head_kinds, kSelfMessageKinds};
    const T scale = static_cast<T>(1.0 / std::sqrt(static_cast<double>(m.head_dim)));
    const auto ria = ad::rot_inv_attention(tape, q, r, s, graph, scale, static_cast<T>(kEps));
    out = ria.out;
    if (!gr.fused_inter_pos.empty()) {
      const Var<T> wi = ad::gather_rows(tape, ria.weights, gr.fused_inter_pos, 0, G);
      StageClock inter_clock(opt.times, &StageTimes::attention_inter_ms);
      // The edge vectors r + s of the world heads, gathered group by group.
      const auto fi = [&](int g) {
        const int64_t c0 = g * m.head_dim, c1 = c0 + m.head_dim;
        return ad::add(tape, ad::gather_rows(tape, r, gr.inter_recv, c0, c1), ad::gather_rows(tape, s, gr.inter_send, c0, c1));
      };
      const Var<T> u = inter_messages(tape, p, cfg, m, at, fi, inter_rot);
      const Var<T> msg_inter = ad::segment_sum(tape, head_scale(tape, wi, u, G), gr.inter_offsets);
      inter_clock.stop();
      out = ad::concat_cols(tape, {ad::add(tape, ad::slice_cols(tape, out, 0, half), msg_inter),
                                   ad::slice_cols(tape, out, half, d)});
    }
  } else {
    // Channels [0, d/2): world heads, [d/2, d): mesh heads.
    const Var<T> qw = ad::slice_cols(tape, q, 0, half), qm = ad::slice_cols(tape, q, half, d);
    const Var<T> rw = ad::slice_cols(tape, r, 0, half), rm = ad::slice_cols(tape, r, half, d);
    const Var<T> sw = ad::slice_cols(tape, s, 0, half), sm = ad::slice_cols(tape, s, half, d);
    // World heads: world patches and inter tokens, one softmax per receiver.
    const EdgeTerms<T> tw = edge_terms(tape, cfg, m, qw, rw, sw, gr.joint_recv, gr.joint_send);
    const Var<T> aw = edge_weights(tape, tw, gr.joint_offsets);
    const Var<T> msg_world = ad::segment_sum(tape, head_scale(tape, ad::mul(tape, aw, is_world), tw.f, G), gr.joint_offsets);
    Var<T> msg_inter;
    if (!gr.inter_pos.empty()) {
      StageClock inter_clock(opt.times, &StageTimes::attention_inter_ms);
      const Var<T> fi = ad::gather_rows(tape, tw.f, gr.inter_pos);
      const Var<T> ai = ad::gather_rows(tape, aw, gr.inter_pos);
      const auto fi_group = [&](int g) { return ad::slice_cols(tape, fi, g * m.head_dim, (g + 1) * m.head_dim); };
      const Var<T> u = inter_messages(tape, p, cfg, m, at, fi_group, inter_rot);
      msg_inter = ad::segment_sum(tape, head_scale(tape, ai, u, G), gr.inter_offsets);
    }
    // Mesh heads: mesh-adjacent patches and the garment's attribute token.
    const EdgeTerms<T> tm = edge_terms(tape, cfg, m, qm, rm, sm, gr.mesh_recv, gr.mesh_send);
    const Var<T> am = edge_weights(tape, tm, gr.mesh_offsets);
    const Var<T> msg_mesh = ad::segment_sum(tape, head_scale(tape, am, tm.f, G), gr.mesh_offsets);

    out = ad::concat_cols(tape, {msg_inter.value ? ad::add(tape, msg_world, msg_inter) : msg_world, msg_mesh});
  }
  edges_clock.stop();
  out = ad::add(tape, ad::mul(tape, out, p(at + "n_weight")), p(at + "n_bias"));
  // Post-LN: patches LN0(x + attn); other tokens get no attention: LN0(2x). Then LN1(y + FFN(y)).
  // The other tokens' update is dead after the last layer (only patch tokens are decoded).
  Var<T> y0 = ad::linear_add(tape, out, p(at + "proj.weight"), p(at + "proj.bias"), Xp);
  attention_clock.stop();
  StageClock ffn_clock(opt.times, &StageTimes::ffn_ms);
  if (!last) y0 = ad::concat_rows(tape, y0, ad::scale(tape, rows_of(st.X, P, st.X.rows), T(2)));
  const Var<T> y = norm(tape, p, pre + "norms.0", y0);
  Streams<T> next;
  next.X = norm(tape, p, pre + "norms.1", ad::add(tape, y, mlp(tape, p, pre + "ffn", 2, true, y)));
  if (!last) {
    next.R = norm(tape, p, pre + "res_norms.0", ad::linear(tape, r, p(at + "r_proj.weight"), p(at + "r_proj.bias")));
    next.S = norm(tape, p, pre + "res_norms.1", ad::linear(tape, s, p(at + "s_proj.weight"), p(at + "s_proj.bias")));
  }
  return next;
}

// Rotation rows R[idx] (identity for idx = -1), as a host array (n, 9).
template <class T>
std::vector<T> frames_of(const ModelInput<T>& in, const std::vector<int32_t>& idx) {
  std::vector<T> R(idx.size() * 9, T(0));
  for (std::size_t k = 0; k < idx.size(); ++k) {
    if (idx[k] < 0) {
      R[9 * k] = R[9 * k + 4] = R[9 * k + 8] = T(1);
    } else {
      std::copy_n(&in.body_rot[9 * idx[k]], 9, &R[9 * k]);
    }
  }
  return R;
}

// Acceleration in the local frame (rows of a_local) -> world (Rᵀ a), de-normalised with the
// velocity statistics (official; add_mean = false scales by the std only), then v = v_base + a,
// x = x_base + v. base: (n, 6) [x, v].
// base_delta (n, 6), when given: the zero-valued gradient path of the base (StateDelta).
template <class T>
Var<T> integrate(ad::Tape<T>& tape, const ModelInput<T>& in, const Var<T>& a_local, const Var<T>& R, bool rotate,
                 const std::vector<T>& base, const Var<T>& base_delta, bool add_mean) {
  const int64_t n = a_local.rows;
  Var<T> a = rotate ? ad::rotate3(tape, R, a_local, /*transpose=*/true) : a_local;
  const std::vector<T> sd(in.std12.begin() + 3, in.std12.begin() + 6), mu(in.mean12.begin() + 3, in.mean12.begin() + 6);
  a = ad::mul(tape, a, constant(tape, sd, 1, 3));
  if (add_mean) a = ad::add(tape, a, constant(tape, mu, 1, 3));
  std::vector<T> bx(n * 3), bv(n * 3);
  for (int64_t i = 0; i < n; ++i)
    for (int c = 0; c < 3; ++c) bx[3 * i + c] = base[6 * i + c], bv[3 * i + c] = base[6 * i + 3 + c];
  Var<T> base_x = constant(tape, bx, n, 3), base_v = constant(tape, bv, n, 3);
  if (base_delta.value) {
    base_x = ad::add(tape, base_x, ad::slice_cols(tape, base_delta, 0, 3));
    base_v = ad::add(tape, base_v, ad::slice_cols(tape, base_delta, 3, 6));
  }
  const Var<T> v = ad::add(tape, a, base_v);
  const Var<T> x = ad::add(tape, v, base_x);
  return ad::concat_cols(tape, {x, v, a});
}

// The gradient path of a garment state s (N, 12) given to forward(): δ = s − sg(s), zero in
// value, and what the input derives linearly from the state, for the vertices (N, 12) and the
// patches (P, 12, the mean over member vertices). Adding them changes no value but lets d/ds
// through the patch embedding input, the decoder's relative states and the integration bases.
template <class T>
struct StateDelta {
  Var<T> vertex, patch;
  bool active() const { return vertex.value != nullptr; }
};

template <class T>
StateDelta<T> state_delta(ad::Tape<T>& tape, const ModelInput<T>& in, const Var<T>& state) {
  StateDelta<T> d;
  if (!state.value) return d;
  LAYERSNET_CHECK(state.rows == in.N && state.cols == 12,
                  "forward: the garment state is (" << state.rows << ", " << state.cols << "), the input has N = " << in.N
                                                    << " vertices of 12 state columns");
  d.vertex = ad::sub(tape, state, tape.constant(state.value, in.N, 12));
  std::vector<T> inv_members(in.P);
  for (int64_t p = 0; p < in.P; ++p)
    inv_members[p] = T(1) / static_cast<T>(std::max(1, in.p2v_offsets[p + 1] - in.p2v_offsets[p]));
  d.patch = ad::mul(tape, ad::segment_sum(tape, ad::gather_rows(tape, d.vertex, in.p2v_vertices), in.p2v_offsets),
                    constant(tape, inv_members, in.P, 1));
  return d;
}

// K Jacobi steps u ← (u + mean of u over the vertex's mesh neighbours) / 2, as
// dataset::smooth_over_mesh does on the carry.  u (N, c) → (N, c).
template <class T>
Var<T> smooth_over_vertex_mesh(ad::Tape<T>& tape, const ModelInput<T>& in, Var<T> u, int iterations) {
  LAYERSNET_CHECK(in.vertex_mesh_offsets.size() == static_cast<std::size_t>(in.N + 1),
                  "model.output_smoothing = " << iterations
                                              << " but the input has no vertex mesh neighbours: build it with "
                                                 "model_input_from_sample and the model's config");
  std::vector<T> half_inv_degree(in.N);
  for (int64_t v = 0; v < in.N; ++v)
    half_inv_degree[v] = T(0.5) / static_cast<T>(in.vertex_mesh_offsets[v + 1] - in.vertex_mesh_offsets[v]);
  const Var<T> weight = constant(tape, half_inv_degree, in.N, 1);
  for (int it = 0; it < iterations; ++it) {
    const Var<T> neighbour_sum =
        ad::segment_sum(tape, ad::gather_rows(tape, u, in.vertex_mesh_neighbours), in.vertex_mesh_offsets);
    u = ad::add(tape, ad::scale(tape, u, 0.5), ad::mul(tape, neighbour_sum, weight));
  }
  return u;
}

// The decoder's outputs in each row's local frame: per patch (P, 3) and per candidate row (Ec, 3),
// scaled by opt.correction_scale.
template <class T>
struct Correction {
  Var<T> patch, candidate;
};

// The body frames R of the patches (P, 9) and the vertices (N, 9), as host arrays and constants,
// made once for the decoder and the integration.
template <class T>
struct Frames {
  std::vector<T> patch_host, vertex_host;
  Var<T> patch, vertex;
};

template <class T>
Frames<T> body_frames(ad::Tape<T>& tape, const ModelInput<T>& in) {
  Frames<T> f{frames_of(in, in.patch_body), frames_of(in, in.vertex_body), {}, {}};
  f.patch = constant(tape, f.patch_host, in.P, 9);
  f.vertex = constant(tape, f.vertex_host, in.N, 9);
  return f;
}

template <class T>
Correction<T> decode(ad::Tape<T>& tape, const ParamView<T>& p, const ModelConfig& cfg, const ModelDims& m,
                     const ModelInput<T>& in, const Var<T>& emb, const Var<T>& body_x, const ForwardOptions& opt,
                     const StateDelta<T>& delta, const Frames<T>& frames) {
  const int64_t N = in.N, P = in.P, d = m.d, U = in.U;
  const bool ret = cfg.rotation_equivalent;
  // Body features with a zero row for "no body vertex within R_b" (index U).
  const Var<T> zero_row = tape.zeros(1, d);
  const Var<T> body_tab = U > 0 ? ad::concat_rows(tape, body_x, zero_row) : zero_row;
  auto body_index = [&](const std::vector<int32_t>& idx) {
    std::vector<int32_t> out(idx);
    for (auto& k : out)
      if (k < 0) k = static_cast<int32_t>(U);
    return out;
  };
  // RET with k channels: φ(R) = W (I_k ⊗ R) Wᵀ, W (d, 3k); k = 1 is the official rank-3 map.
  Var<T> W, Wt;
  if (ret) {
    W = rotation_map_impl(tape, p, cfg, "decoder.rot_mapping.weight");  // (d, 3k)
    Wt = transpose_of(tape, W);                                          // (3k, d)
  }
  // (I_k ⊗ R_i) z_i for every row i: z (n, 3k) read as n·k 3-vectors, R (n, 9) a constant.
  auto rotate_k_blocks = [&](const Var<T>& R, const Var<T>& z, int64_t k) {
    const int64_t n = z.rows;
    if (k == 1) return ad::rotate3(tape, R, z);
    std::vector<T> R_rep(n * k * 9);
    for (int64_t i = 0; i < n; ++i)
      for (int64_t j = 0; j < k; ++j) std::copy_n(&R.value[9 * i], 9, &R_rep[9 * (i * k + j)]);
    const Var<T> y = ad::rotate3(tape, constant(tape, R_rep, n * k, 9), ad::reshape(z, n * k, 3));
    return ad::reshape(y, n, 3 * k);
  };
  auto rotate_blocks = [&](const Var<T>& R, const Var<T>& z) { return rotate_k_blocks(R, z, cfg.decoder_ret_channels); };

  const std::vector<T>& Rp_host = frames.patch_host;
  const Var<T>& Rp = frames.patch;
  const Var<T> phi_p = ad::gather_rows(tape, body_tab, body_index(in.patch_body));
  const Var<T> phi_v = ad::gather_rows(tape, body_tab, body_index(in.vertex_body));
  const std::vector<T>& Rv_host = frames.vertex_host;
  const Var<T>& Rv = frames.vertex;
  // Candidate rows: owning vertex, its frame, and R_v (s_v − s_p) as four 3-vectors (raw units),
  // written straight into tape constants (every entry below; no host copy to zero and copy over).
  const int64_t Ec = static_cast<int64_t>(in.cand_patches.size());
  std::vector<int32_t> cand_vertex(Ec);
  Var<T> rel_v = tape.new_var(Ec, 12, false);
  const Var<T> Re_v = tape.new_var(Ec, 9, false);
  T *rel = rel_v.value, *Re = Re_v.value;
  for (int64_t v = 0; v < N; ++v)
    for (int32_t k = in.cand_offsets[v]; k < in.cand_offsets[v + 1]; ++k) {
      cand_vertex[k] = static_cast<int32_t>(v);
      const T* R = &Rv_host[9 * v];
      std::copy_n(R, 9, &Re[9 * k]);
      for (int blk = 0; blk < 4; ++blk) {
        T dlt[3];
        for (int c = 0; c < 3; ++c)
          dlt[c] = in.state[12 * v + 3 * blk + c] - in.patch_state[12 * in.cand_patches[k] + 3 * blk + c];
        for (int c = 0; c < 3; ++c)
          rel[12 * k + 3 * blk + c] = ret ? R[3 * c] * dlt[0] + R[3 * c + 1] * dlt[1] + R[3 * c + 2] * dlt[2] : dlt[c];
      }
    }
  if (delta.active()) {  // d(s_v − s_p), rotated by R_v per 3-vector as rel is
    const Var<T> d_rel = ad::sub(tape, ad::gather_rows(tape, delta.vertex, cand_vertex),
                                 ad::gather_rows(tape, delta.patch, in.cand_patches));
    rel_v = ad::add(tape, rel_v, ret ? rotate_k_blocks(Re_v, d_rel, 4) : d_rel);
  }
  // Row i of a per-vertex (or per-patch) feature table f (·, dim) picked by rows[i], each 3-vector
  // turned into frame R_i (RET; R_host (n, 9)): (n, dim).
  auto rotated_rows = [&](const T* R_host, const std::vector<T>& f, const std::vector<int32_t>& rows, int dim) {
    const int64_t n = static_cast<int64_t>(rows.size());
    const Var<T> out = tape.new_var(n, dim, false);
    for (int64_t k = 0; k < n; ++k) {
      const T* R = &R_host[9 * k];
      const T* x = &f[dim * static_cast<int64_t>(rows[k])];
      T* o = &out.value[dim * k];
      for (int blk = 0; blk < dim / 3; ++blk)
        for (int c = 0; c < 3; ++c)
          o[3 * blk + c] = ret ? R[3 * c] * x[3 * blk] + R[3 * c + 1] * x[3 * blk + 1] + R[3 * c + 2] * x[3 * blk + 2]
                               : x[3 * blk + c];
    }
    return out;
  };
  // The vertex's local features per candidate row, in the vertex's frame.
  const bool local = cfg.vertex_local_features;
  LAYERSNET_CHECK(!local || in.vertex_local.size() == static_cast<std::size_t>(N * kVertexLocalDim),
                  "model.vertex_local_features is on but the input has no vertex_local features (N = " << N << ")");
  const Var<T> loc_v = local ? rotated_rows(Re, in.vertex_local, cand_vertex, kVertexLocalDim) : Var<T>{};
  // The wind force per candidate row and per patch, in the row's frame. A scene without wind
  // skips it: a zero input adds nothing.
  const bool wind = cfg.wind_force_input && !in.wind_force.empty();
  LAYERSNET_CHECK(!cfg.wind_force_input || !in.has_wind || wind,
                  "model.wind_force_input is on but the windy input has no wind_force: build it with model_input_from_sample");
  Var<T> wind_v, wind_p;
  if (wind) {
    std::vector<int32_t> patches(P);
    for (int64_t i = 0; i < P; ++i) patches[i] = static_cast<int32_t>(i);
    wind_v = rotated_rows(Re, in.wind_force, cand_vertex, 3);
    wind_p = rotated_rows(Rp_host.data(), in.wind_force_patch, patches, 3);
  }
  // The vertex's own velocity base per candidate row, [c_v, c_v − c̄_p] / σ_v in the row's frame
  // (p the row's patch). A carried base is implied (run/config.cpp) and checked in forward().
  const bool vertex_base = cfg.vertex_base_input;
  Var<T> base_in_v;
  if (vertex_base) {
    std::vector<T> table(Ec * 6);
    std::vector<int32_t> rows(Ec);
    for (int64_t k = 0; k < Ec; ++k) {
      rows[k] = static_cast<int32_t>(k);
      const int64_t v = cand_vertex[k], patch = in.cand_patches[k];
      for (int c = 0; c < 3; ++c) {
        const T inv_std = T(1) / in.std12[3 + c];
        table[6 * k + c] = in.body_carry[3 * v + c] * inv_std;
        table[6 * k + 3 + c] = (in.body_carry[3 * v + c] - in.body_carry_patch[3 * patch + c]) * inv_std;
      }
    }
    base_in_v = rotated_rows(Re, table, rows, 6);
  }
  // First-layer weights and inputs: the extra columns sit after rel's 12, local, base, then wind;
  // the patch branch (rel = 0) has only the wind's.
  auto with_extra_weight = [&](const Var<T>& W_first, bool vertex_rows) {
    std::vector<Var<T>> parts{ad::slice_cols(tape, W_first, 0, 12)};
    if (vertex_rows && local) parts.push_back(p("decoder.local.weight"));
    if (vertex_rows && vertex_base) parts.push_back(p("decoder.base.weight"));
    if (wind) parts.push_back(p("decoder.wind.weight"));
    if (parts.size() == 1) return W_first;
    parts.push_back(ad::slice_cols(tape, W_first, 12, W_first.cols));
    return ad::concat_cols(tape, std::span<const Var<T>>(parts));
  };
  auto with_extra_input = [&](const Var<T>& rel_part, const Var<T>& e_part, const Var<T>& h_part, bool vertex_rows) {
    std::vector<Var<T>> parts{rel_part};
    if (vertex_rows && local) parts.push_back(loc_v);
    if (vertex_rows && vertex_base) parts.push_back(base_in_v);
    if (wind) parts.push_back(vertex_rows ? wind_v : wind_p);
    parts.push_back(e_part);
    parts.push_back(h_part);
    return ad::concat_cols(tape, std::span<const Var<T>>(parts));
  };

  // The decoder MLP decoder.proj with its first-layer weight given (factored and/or with local columns).
  auto decode = [&](const Var<T>& f, const Var<T>& W_first) {
    const std::array<Var<T>, 3> weights{W_first, p("decoder.proj.1.weight"), p("decoder.proj.2.weight")};
    const std::array<Var<T>, 3> biases{p("decoder.proj.0.bias"), p("decoder.proj.1.bias"), p("decoder.proj.2.bias")};
    return ad::mlp(tape, f, std::span<const Var<T>>(weights), std::span<const Var<T>>(biases), false);
  };

  Var<T> a_p, a_e;  // decoder outputs (local frame): per patch (P, 3), per candidate (Ec, 3)
  if (ret && opt.factor_decoder) {
    // First layer on [rel, R Wᵀe, R Wᵀh] with weight [W1_rel | W1_e W | W1_h W] (exact, rank 3k).
    const Var<T> W1 = p("decoder.proj.0.weight");
    const Var<T> M = ad::concat_cols(tape, {ad::slice_cols(tape, W1, 0, 12),
                                            ad::linear(tape, ad::slice_cols(tape, W1, 12, 12 + d), Wt),
                                            ad::linear(tape, ad::slice_cols(tape, W1, 12 + d, 12 + 2 * d), Wt)});
    const Var<T> z_p = ad::linear(tape, emb, Wt);  // Wᵀ e_p  (P, 3k)
    const Var<T> feat_p = with_extra_input(tape.zeros(P, 12), rotate_blocks(Rp, z_p),
                                           rotate_blocks(Rp, ad::linear(tape, phi_p, Wt)), false);
    const Var<T> zh_v = rotate_blocks(Rv, ad::linear(tape, phi_v, Wt));  // (I⊗R_v) Wᵀ h_v  (N, 3k)
    const Var<T> ze_v = rotate_blocks(Re_v, ad::gather_rows(tape, z_p, in.cand_patches));
    const Var<T> feat_v = with_extra_input(rel_v, ze_v, ad::gather_rows(tape, zh_v, cand_vertex), true);
    a_p = decode(feat_p, with_extra_weight(M, false));
    a_e = decode(feat_v, with_extra_weight(M, true));
  } else {
    // Patch branch: [0 (12), φ(R_p) e_p, φ(R_p) h_p]; vertex branch: [rel, φ(R_v) e_p, φ(R_v) h_v].
    // k = 1: the fused W R Wᵀ op; k > 1: W (I⊗R) Wᵀ composed.
    auto phi = [&](const Var<T>& R, const Var<T>& x) {
      if (cfg.decoder_ret_channels == 1) return ad::rot_map_apply(tape, W, R, x);
      return ad::linear(tape, rotate_blocks(R, ad::linear(tape, x, Wt)), W);
    };
    const Var<T> He_p = ret ? phi(Rp, emb) : emb;
    const Var<T> Hh_p = ret ? phi(Rp, phi_p) : phi_p;
    const Var<T> W1 = p("decoder.proj.0.weight");
    a_p = decode(with_extra_input(tape.zeros(P, 12), He_p, Hh_p, false), with_extra_weight(W1, false));
    Var<T> He_v, Hh_v;
    if (ret) {
      const Var<T> z_e = rotate_blocks(Re_v, ad::gather_rows(tape, ad::linear(tape, emb, Wt), in.cand_patches));
      He_v = ad::linear(tape, z_e, W);  // W (I⊗R_v) Wᵀ e_p  (Ec, d)
      Hh_v = ad::gather_rows(tape, phi(Rv, phi_v), cand_vertex);
    } else {
      He_v = ad::gather_rows(tape, emb, in.cand_patches);
      Hh_v = ad::gather_rows(tape, phi_v, cand_vertex);
    }
    a_e = decode(with_extra_input(rel_v, He_v, Hh_v, true), with_extra_weight(W1, true));
  }
  if (opt.correction_scale != 1.0) {  // carried bases: the prediction is affine in a, so this scales the correction
    a_p = ad::scale(tape, a_p, static_cast<T>(opt.correction_scale));
    a_e = ad::scale(tape, a_e, static_cast<T>(opt.correction_scale));
  }
  return {a_p, a_e};
}

// The next state from the decoder's outputs a (zero: the velocity base alone), each integrated in
// its row's frame.
template <class T>
Predictions<T> predict(ad::Tape<T>& tape, const ModelConfig& cfg, const ModelInput<T>& in, const Correction<T>& a,
                       const StateDelta<T>& delta, const Frames<T>& frames) {
  const int64_t N = in.N, P = in.P;
  const bool ret = cfg.rotation_equivalent;
  const Var<T>& a_p = a.patch;
  const Var<T>& a_e = a.candidate;
  const Var<T>& Rp = frames.patch;
  const Var<T>& Rv = frames.vertex;
  // Velocity bases: the cloth's own velocity (inertia), or in.body_carry (c, or c + v_t − c_t).
  // The vertex base is then c_v − c̄_p (c̄_p the patch mean), so x_v = x_t + c_v + a_p + a_v. c and
  // c_t are held constant under StateDelta (their dependence on the state is the body's rotation),
  // and the outputs are not offset by the mean velocity: a zero output is the carried step.
  const bool carried = cfg.velocity_base != "inertia";  // its inputs are checked in forward()
  const std::vector<T>& carry_p = in.body_carry_patch;
  std::vector<T> base_p(P * 6);
  for (int64_t i = 0; i < P; ++i) {
    std::copy_n(&in.patch_state[12 * i], 6, &base_p[6 * i]);
    if (carried) std::copy_n(&carry_p[3 * i], 3, &base_p[6 * i + 3]);
  }
  Var<T> d_base_p = delta.active() ? ad::slice_cols(tape, delta.patch, 0, 6) : Var<T>{};
  const bool body_only = cfg.velocity_base == "body" || cfg.velocity_base == "physics";  // no v_t in the base
  if (body_only && delta.active()) d_base_p = ad::concat_cols(tape, {ad::slice_cols(tape, delta.patch, 0, 3), tape.zeros(P, 3)});
  const Var<T> pred_patch = integrate(tape, in, a_p, Rp, ret, base_p, d_base_p, !carried);

  std::vector<T> inv_count(N);
  for (int64_t v = 0; v < N; ++v)
    inv_count[v] = T(1) / static_cast<T>(std::max(1, in.cand_offsets[v + 1] - in.cand_offsets[v]));
  const Var<T> a_v = ad::mul(tape, ad::segment_sum(tape, a_e, in.cand_offsets), constant(tape, inv_count, N, 1));
  std::vector<T> base_v(N * 6);  // s_v − s_own: the vertex relative to its own patch
  for (int64_t v = 0; v < N; ++v)
    for (int c = 0; c < 6; ++c) base_v[6 * v + c] = in.state[12 * v + c] - in.patch_state[12 * in.own_patch[v] + c];
  if (carried)
    for (int64_t v = 0; v < N; ++v)
      for (int c = 0; c < 3; ++c) base_v[6 * v + 3 + c] = in.body_carry[3 * v + c] - carry_p[3 * in.own_patch[v] + c];
  Var<T> d_base_v =
      delta.active() ? ad::sub(tape, ad::slice_cols(tape, delta.vertex, 0, 6), ad::gather_rows(tape, d_base_p, in.own_patch))
                     : Var<T>{};
  if (body_only && delta.active()) d_base_v = ad::concat_cols(tape, {ad::slice_cols(tape, d_base_v, 0, 3), tape.zeros(N, 3)});
  const Var<T> pred_rel = integrate(tape, in, a_v, Rv, ret, base_v, d_base_v, !carried);
  Predictions<T> out;
  out.vertex = ad::add(tape, pred_rel, ad::gather_rows(tape, pred_patch, in.own_patch));
  out.patch = pred_patch;
  // The correction is the acceleration column (world axes), which x and v contain once each:
  // replacing it by f(a) moves all three by f(a) − a.
  auto transform_correction = [&](auto&& f) {
    const Var<T> a = ad::slice_cols(tape, out.vertex, 6, 9);
    const Var<T> change = ad::sub(tape, f(a), a);
    out.vertex = ad::add(tape, out.vertex, ad::concat_cols(tape, {change, change, change}));
  };
  if (cfg.output_smoothing > 0)
    transform_correction([&](const Var<T>& a) { return smooth_over_vertex_mesh(tape, in, a, cfg.output_smoothing); });
  if (cfg.physics_step_correction == "solved") {
    LAYERSNET_CHECK(!in.system_offsets.empty(), "model.physics_step_correction = \"solved\" but the input has no "
                                                "physics system: build it with model_input_from_sample");
    const ad::BlockSpd<T> system{in.system_offsets, in.system_columns, in.system_blocks, in.system_scale,
                                 cfg.physics_step_cg_iterations, T(1e-6)};
    transform_correction([&](const Var<T>& a) { return ad::block_spd_solve(tape, system, a); });
  }
  return out;
}

// Rows each stage works on (StageTimes' work fields).
template <class T>
void count_work(const ModelInput<T>& in, const Graph<T>& gr, StageTimes& t) {
  t.patch_rows = in.P;
  t.token_rows = gr.P + gr.A + gr.T_rows;
  t.body_tokens = in.U;
  t.ext_tokens = gr.T_rows - in.U;
  t.inter_rows = static_cast<int64_t>(gr.inter_pos.size());
  t.world_rows = static_cast<int64_t>(gr.joint_recv.size()) - t.inter_rows;
  t.body_rows = static_cast<int64_t>(in.body_tokens.size());
  t.mesh_rows = static_cast<int64_t>(gr.mesh_recv.size());
  t.vertex_rows = in.N;
  t.candidate_rows = static_cast<int64_t>(in.cand_patches.size());
}

}  // namespace

template <class T>
Predictions<T> forward(ad::Tape<T>& tape, ad::ParamStore<T>& params, const ModelConfig& cfg, const ModelInput<T>& in,
                       const ForwardOptions& options, const Var<T>& garment_state) {
  StageTimes* times = options.times;
  if (times) *times = StageTimes{};
  StageClock total_clock(times, &StageTimes::total_ms);
  const ModelDims m = model_dims(cfg);
  const ParamView<T> p{params};
  if (options.correction_scale == 0.0) {
    // The velocity base alone: a zero correction needs no network (and reads no weight).
    const Correction<T> none{tape.zeros(in.P, 3), tape.zeros(static_cast<int64_t>(in.cand_patches.size()), 3)};
    return predict(tape, cfg, in, none, state_delta(tape, in, garment_state), body_frames(tape, in));
  }
  StageClock graph_clock(times, &StageTimes::graph_ms);
  const Graph<T> gr = build_graph(in, m.groups);
  graph_clock.stop();
  const int64_t P = in.P, A = in.A, U = in.U;
  if (times) count_work(in, gr, *times);
  LAYERSNET_CHECK(cfg.velocity_base == "inertia" || (in.body_carry.size() == static_cast<std::size_t>(in.N * 3) &&
                                                     in.body_carry_patch.size() == static_cast<std::size_t>(P * 3)),
                  "model.velocity_base = \"" << cfg.velocity_base << "\" but the input lacks body_carry (N = " << in.N
                                              << ", 3) or body_carry_patch (P = " << P
                                              << ", 3): build it with model_input_from_sample");

  // ---- token encoders ---------------------------------------------------------------------------------
  StageClock encoder_clock(times, &StageTimes::encoder_ms);
  const StateDelta<T> delta = state_delta(tape, in, garment_state);
  Var<T> patch_in = constant(tape, in.patch_norm, P, 12);
  if (delta.active()) {  // patch_norm = (patch mean − μ) / σ
    std::vector<T> inv_std(12);
    for (int c = 0; c < 12; ++c) inv_std[c] = T(1) / in.std12[c];
    patch_in = ad::add(tape, patch_in, ad::mul(tape, delta.patch, constant(tape, inv_std, 1, 12)));
  }
  Var<T> patch_x = mlp(tape, p, "embed.input", 2, true, patch_in);
  if (cfg.patch_base_input) {  // implies a carried base (run/config.cpp), whose inputs are checked above
    std::vector<T> base(P * 3);
    for (int64_t i = 0; i < P; ++i)
      for (int c = 0; c < 3; ++c) base[3 * i + c] = in.body_carry_patch[3 * i + c] / in.std12[3 + c];
    patch_x = ad::add(tape, patch_x, ad::linear(tape, constant(tape, base, P, 3), p("embed.base.weight")));
  }
  if (cfg.wind_force_input && !in.wind_force_patch.empty())
    patch_x = ad::add(tape, patch_x, ad::linear(tape, constant(tape, in.wind_force_patch, P, 3), p("embed.wind_force.weight")));
  const Var<T> attr_x = mlp(tape, p, "embed.attr", 2, true, constant(tape, in.attr, A, 5));
  StageClock body_clock(U > 0 ? times : nullptr, &StageTimes::encoder_body_ms);  // stays 0 without body tokens
  const Var<T> body_x = U > 0 ? mlp(tape, p, "embed.input", 2, true, constant(tape, in.body_norm, U, 12)) : Var<T>{};
  body_clock.stop();
  Var<T> ext = mlp(tape, p, "embed.gravity", 2, true, constant(tape, in.gravity, 1, ModelDims::kGravityDim));
  if (in.has_wind)
    ext = ad::concat_rows(tape, mlp(tape, p, "embed.wind", 2, true, constant(tape, in.wind, 1, ModelDims::kWindDim)), ext);
  const Var<T> h_x = U > 0 ? ad::concat_rows(tape, body_x, ext) : ext;  // (T, d): body, [wind], gravity
  const Var<T> pa_x = ad::concat_rows(tape, patch_x, attr_x);            // (P + A, d)
  const Var<T> all_x = ad::concat_rows(tape, pa_x, h_x);                 // (P + A + T, d)

  Streams<T> st;
  st.R = norm(tape, p, "embed.receiver_norm", mlp(tape, p, "embed.receiver", 2, true, patch_x));
  st.S = norm(tape, p, "embed.sender_norm", mlp(tape, p, "embed.sender", 2, true, all_x));
  // Patch and attribute tokens are normalised, body/wind/gravity tokens are not (official).
  st.X = ad::concat_rows(tape, norm(tape, p, "embed.particle_norm", pa_x), h_x);
  encoder_clock.stop();

  // ---- simulator -----------------------------------------------------------------------------------------
  const Var<T> inter_rot = constant(tape, gr.inter_rot, static_cast<int64_t>(gr.inter_pos.size()), 9);
  const Var<T> is_world = constant(tape, gr.joint_is_world, static_cast<int64_t>(gr.joint_recv.size()), 1);
  for (int l = 0; l < m.layers; ++l) st = encoder_layer(tape, p, cfg, m, gr, inter_rot, is_world, l, st, options);

  // ---- decoder ---------------------------------------------------------------------------------------------
  StageClock decoder_clock(times, &StageTimes::decoder_ms);
  const Frames<T> frames = body_frames(tape, in);
  return predict(tape, cfg, in, decode(tape, p, cfg, m, in, rows_of(st.X, 0, P), body_x, options, delta, frames), delta,
                 frames);
}

template <class T>
Var<T> rotation_map(ad::Tape<T>& tape, ad::ParamStore<T>& params, const ModelConfig& cfg, const std::string& name) {
  return rotation_map_impl(tape, ParamView<T>{params}, cfg, name);
}

template Var<float> rotation_map(ad::Tape<float>&, ad::ParamStore<float>&, const ModelConfig&, const std::string&);
template Var<double> rotation_map(ad::Tape<double>&, ad::ParamStore<double>&, const ModelConfig&, const std::string&);
template Predictions<float> forward(ad::Tape<float>&, ad::ParamStore<float>&, const ModelConfig&,
                                    const ModelInput<float>&, const ForwardOptions&, const Var<float>&);
template Predictions<double> forward(ad::Tape<double>&, ad::ParamStore<double>&, const ModelConfig&,
                                     const ModelInput<double>&, const ForwardOptions&, const Var<double>&);

}  // namespace layersnet::model
