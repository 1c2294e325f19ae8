#include "autodiff/ops_attention.h"

#include "autodiff/ops_graph.h"
#include "autodiff/row_blocks.h"

#include <Eigen/Core>

#include <algorithm>
#include <cmath>
#include <limits>

namespace layersnet::ad {

namespace {

constexpr int64_t kParallelMin = int64_t{1} << 14;

// Sizes and pointers shared by the kernels. All matrices row-major.
template <class T>
struct RiaProblem {
  int64_t n_recv = 0, n_send = 0, heads = 0, dim = 0;  // P, M, H, D
  const int32_t* offsets = nullptr;                    // (P+1)
  const int32_t* senders = nullptr;                    // (E)
  const int32_t* kinds = nullptr;                      // (E)
  const uint32_t* head_kinds = nullptr;                // (H)
  uint32_t message_kinds = 0;
  T scale = 0, eps = 0;
  const T* q = nullptr;  // (P, H*D)
  const T* r = nullptr;  // (P, H*D)
  const T* s = nullptr;  // (M, H*D)

  int64_t width() const { return heads * dim; }
  bool attends(int64_t e, int64_t h) const { return (head_kinds[h] >> kinds[e]) & 1u; }
  bool messages(int64_t e) const { return (message_kinds >> kinds[e]) & 1u; }
};

// One head's D-vector inside a row. Eigen vectorises the dot products and norms (a plain
// loop would not: float sums may not be reassociated without -ffast-math).
template <class T, int kD>
using HeadVec = Eigen::Map<const Eigen::Matrix<T, (kD > 0 ? kD : Eigen::Dynamic), 1>>;
template <class T, int kD>
using HeadVecMut = Eigen::Map<Eigen::Matrix<T, (kD > 0 ? kD : Eigen::Dynamic), 1>>;

// Forward for all receivers. a, rho, w, cq = q.(s + r): (E, H); out: (P, H*D), overwritten.
// kD > 0 fixes the head width at compile time (unrolled, vectorised inner loops).
template <class T, int kD>
void ria_forward(const RiaProblem<T>& pb, T* a, T* rho, T* cq, T* w, T* out) {
  const int64_t H = pb.heads, D = kD > 0 ? kD : pb.dim, C = pb.width();
#pragma omp parallel for schedule(dynamic, 16) if (int64_t{pb.offsets[pb.n_recv]} * C > kParallelMin)
  for (int64_t i = 0; i < pb.n_recv; ++i) {
    const int64_t e0 = pb.offsets[i], e1 = pb.offsets[i + 1];
    std::fill_n(out + i * C, C, T(0));
    for (int64_t h = 0; h < H; ++h) {
      const HeadVec<T, kD> qi(pb.q + i * C + h * D, D), ri(pb.r + i * C + h * D, D);
      T zmax = -std::numeric_limits<T>::infinity();
      for (int64_t e = e0; e < e1; ++e) {
        const int64_t k = e * H + h;
        if (!pb.attends(e, h)) {
          a[k] = 0, rho[k] = 0, cq[k] = 0, w[k] = 0;
          continue;
        }
        const HeadVec<T, kD> sj(pb.s + int64_t{pb.senders[e]} * C + h * D, D);
        const T dist2 = (ri - sj).squaredNorm();
        const T c = qi.dot(sj + ri);
        rho[k] = std::sqrt(dist2 + pb.eps * pb.eps);
        cq[k] = c;
        a[k] = T(2) * pb.scale * c / rho[k];  // the logit, until normalised below
        zmax = std::max(zmax, a[k]);
      }
      T sum = 0;
      for (int64_t e = e0; e < e1; ++e)
        if (pb.attends(e, h)) sum += (a[e * H + h] = std::exp(a[e * H + h] - zmax));
      if (sum == T(0)) continue;  // no attended edge: zero output for this head
      const T inv = T(1) / sum;
      HeadVecMut<T, kD> oi(out + i * C + h * D, D);
      for (int64_t e = e0; e < e1; ++e) {
        const int64_t k = e * H + h;
        if (!pb.attends(e, h)) continue;
        a[k] *= inv;
        w[k] = a[k] / rho[k];
        if (!pb.messages(e)) continue;
        const HeadVec<T, kD> sj(pb.s + int64_t{pb.senders[e]} * C + h * D, D);
        oi += w[k] * (sj + ri);
      }
    }
  }
}

// Backward, receiver part. a, rho, cq from the forward; g_out: (P, H*D); g_w: (E, H);
// dw: (E, H) scratch. Adds into gq, gr (P, H*D) when non-null and writes the per-edge sender
// gradient ds_edge (E, H*D) when non-null.
template <class T, int kD>
void ria_backward_receivers(const RiaProblem<T>& pb, const T* a, const T* rho, const T* cq, const T* g_out,
                            const T* g_w, T* dw_buf, T* gq, T* gr, T* ds_edge) {
  const int64_t H = pb.heads, D = kD > 0 ? kD : pb.dim, C = pb.width();
  const T two_scale = T(2) * pb.scale;
#pragma omp parallel for schedule(dynamic, 16) if (int64_t{pb.offsets[pb.n_recv]} * C > kParallelMin)
  for (int64_t i = 0; i < pb.n_recv; ++i) {
    const int64_t e0 = pb.offsets[i], e1 = pb.offsets[i + 1];
    for (int64_t h = 0; h < H; ++h) {
      const HeadVec<T, kD> qi(pb.q + i * C + h * D, D), ri(pb.r + i * C + h * D, D), gi(g_out + i * C + h * D, D);
      // Softmax backward needs sum_e a_e * dL/da_e over the segment first; dL/dw_e comes
      // from the message (if any) and from the weights output.
      T sum_ada = 0;
      for (int64_t e = e0; e < e1; ++e) {
        if (!pb.attends(e, h)) continue;
        const int64_t k = e * H + h;
        T dw = g_w[k];
        if (pb.messages(e)) dw += gi.dot(HeadVec<T, kD>(pb.s + int64_t{pb.senders[e]} * C + h * D, D) + ri);
        dw_buf[k] = dw;
        sum_ada += a[k] * dw / rho[k];
      }
      for (int64_t e = e0; e < e1; ++e) {
        if (!pb.attends(e, h)) continue;  // its ds_edge slice is never read
        const int64_t k = e * H + h;
        const HeadVec<T, kD> sj(pb.s + int64_t{pb.senders[e]} * C + h * D, D);
        const T dw = dw_buf[k];
        const T inv_rho = T(1) / rho[k];
        const T da = dw * inv_rho;                // w = a / rho
        const T dz = a[k] * (da - sum_ada);       // softmax
        const T c = cq[k];
        const T dc = two_scale * dz * inv_rho;    // z = 2 scale c / rho
        const T drho = -(a[k] * dw + two_scale * c * dz) * inv_rho * inv_rho;
        const T du_coef = drho * inv_rho;         // rho = sqrt(|u|^2 + eps^2), u = r - s
        const T msg = pb.messages(e) ? a[k] * inv_rho : T(0);
        // p = s + r enters c (via q) and the message; u = r - s enters rho.
        if (gq) HeadVecMut<T, kD>(gq + i * C + h * D, D) += dc * (sj + ri);
        if (gr) HeadVecMut<T, kD>(gr + i * C + h * D, D) += msg * gi + dc * qi + du_coef * (ri - sj);
        if (ds_edge) HeadVecMut<T, kD>(ds_edge + e * C + h * D, D) = msg * gi + dc * qi - du_coef * (ri - sj);
      }
    }
  }
}

// Head widths used by LayersNet (16 in the encoder) get a compile-time specialisation.
template <class T>
void ria_forward_any(const RiaProblem<T>& pb, T* a, T* rho, T* cq, T* w, T* out) {
  if (pb.dim == 16) ria_forward<T, 16>(pb, a, rho, cq, w, out);
  else ria_forward<T, 0>(pb, a, rho, cq, w, out);
}
template <class T>
void ria_backward_receivers_any(const RiaProblem<T>& pb, const T* a, const T* rho, const T* cq, const T* g_out,
                                const T* g_w, T* dw_buf, T* gq, T* gr, T* ds_edge) {
  if (pb.dim == 16) ria_backward_receivers<T, 16>(pb, a, rho, cq, g_out, g_w, dw_buf, gq, gr, ds_edge);
  else ria_backward_receivers<T, 0>(pb, a, rho, cq, g_out, g_w, dw_buf, gq, gr, ds_edge);
}

// gs[j] += sum over edges of sender j (in edge order) of ds_edge[e], for the head slices
// that attend to the edge (the others are never written).
// by_sender: (M+1) CSR offsets, edges: (E) edge ids grouped by sender, ascending.
template <class T, int kD>
void ria_backward_senders(const RiaProblem<T>& pb, const int32_t* by_sender, const int32_t* edges, const T* ds_edge,
                          T* gs) {
  const int64_t H = pb.heads, D = kD > 0 ? kD : pb.dim, C = pb.width();
#pragma omp parallel for schedule(static) if (int64_t{by_sender[pb.n_send]} * C > kParallelMin)
  for (int64_t j = 0; j < pb.n_send; ++j) {
    T* dst = gs + j * C;
    for (int64_t k = by_sender[j]; k < by_sender[j + 1]; ++k) {
      const int64_t e = edges[k];
      const T* src = ds_edge + e * C;
      for (int64_t h = 0; h < H; ++h)
        if (pb.attends(e, h)) HeadVecMut<T, kD>(dst + h * D, D) += HeadVec<T, kD>(src + h * D, D);
    }
  }
}

// Counting sort of the edges by sender (stable: ascending edge id within a sender).
void transpose_csr(std::span<const int32_t> senders, int64_t n_send, int32_t* by_sender, int32_t* edges) {
  std::fill_n(by_sender, n_send + 1, 0);
  for (int32_t j : senders) ++by_sender[j + 1];
  for (int64_t j = 0; j < n_send; ++j) by_sender[j + 1] += by_sender[j];
  // by_sender[j] doubles as the fill cursor of sender j, then is shifted back (no allocation).
  for (std::size_t e = 0; e < senders.size(); ++e) edges[by_sender[senders[e]]++] = static_cast<int32_t>(e);
  for (int64_t j = n_send; j > 0; --j) by_sender[j] = by_sender[j - 1];
  by_sender[0] = 0;
}

template <class T>
RiaProblem<T> make_problem(const RiaParams<T>& p, const Var<T>& q, const Var<T>& r, const Var<T>& s) {
  RiaProblem<T> pb;
  pb.n_recv = q.rows;
  pb.n_send = s.rows;
  pb.heads = static_cast<int64_t>(p.head_kinds.size());
  pb.dim = p.head_dim;
  pb.offsets = p.offsets.data();
  pb.senders = p.senders.data();
  pb.kinds = p.kinds.data();
  pb.head_kinds = p.head_kinds.data();
  pb.message_kinds = p.message_kinds;
  pb.scale = p.scale;
  pb.eps = p.eps;
  pb.q = q.value;
  pb.r = r.value;
  pb.s = s.value;
  return pb;
}

}  // namespace

// Node: in[0] = q, in[1] = r, in[2] = s, in[3] = the weights output (a second output: its
// gradient is read, never written); RiaParams;
// saved = [a (E*H) | rho (E*H) | cq = q.(s + r) (E*H)]; backward's dw (E*H) and ds_edge
// (E*H*D, only when s needs a gradient) are backward scratch.
template <class T>
RiaResult<T> rot_inv_attention(Tape<T>& tape, const Var<T>& q, const Var<T>& r, const Var<T>& s,
                               const RiaGraph& graph, T scale, T eps) {
  const auto H = static_cast<int64_t>(graph.head_kinds.size());
  const auto n_edges = static_cast<int64_t>(graph.senders.size());
  LAYERSNET_CHECK(H > 0 && q.cols % H == 0, "rot_inv_attention: " << q.cols << " columns do not split into " << H
                                                                    << " heads (one head_kinds entry per head)");
  LAYERSNET_CHECK(r.rows == q.rows && r.cols == q.cols && s.cols == q.cols,
                  "rot_inv_attention: q (" << q.rows << ", " << q.cols << "), r (" << r.rows << ", " << r.cols
                                           << "), s (" << s.rows << ", " << s.cols
                                           << "); q and r must match and s needs the same width");
  LAYERSNET_CHECK(static_cast<int64_t>(graph.kinds.size()) == n_edges,
                  "rot_inv_attention: " << graph.kinds.size() << " edge kinds for " << n_edges << " edges");
  LAYERSNET_CHECK(static_cast<int64_t>(graph.offsets.size()) == q.rows + 1,
                  "rot_inv_attention: offsets need P+1 = " << q.rows + 1 << " entries, got " << graph.offsets.size());
  LAYERSNET_CHECK(eps > T(0), "rot_inv_attention: eps must be positive, got " << eps);
  check_csr("rot_inv_attention", graph.offsets, n_edges);
  check_indices("rot_inv_attention senders", graph.senders, s.rows);
  check_indices("rot_inv_attention kinds", graph.kinds, 32);

  // Views of the caller's graph for the forward; the node keeps copies.
  RiaParams<T> params{.offsets = graph.offsets,
                      .senders = graph.senders,
                      .kinds = graph.kinds,
                      .head_kinds = graph.head_kinds,
                      .message_kinds = graph.message_kinds,
                      .head_dim = q.cols / H,
                      .scale = scale,
                      .eps = eps,
                      .sender_offsets = {},
                      .edges_by_sender = {}};
  const RiaProblem<T> pb = make_problem(params, q, r, s);

  const bool grad = tape.wants_grad({q, r, s});
  RiaResult<T> res{tape.new_var(q.rows, q.cols, grad), tape.new_var(n_edges, H, grad)};
  const bool s_grad = grad && s.grad;
  const int64_t EH = n_edges * H;
  T* saved = tape.scratch(static_cast<std::size_t>(3 * EH));
  ria_forward_any(pb, saved, saved + EH, saved + 2 * EH, res.weights.value, res.out.value);
  if (!grad) return res;

  params.offsets = tape.copy_to_arena(graph.offsets);
  params.senders = tape.copy_to_arena(graph.senders);
  params.kinds = tape.copy_to_arena(graph.kinds);
  params.head_kinds = tape.copy_to_arena(graph.head_kinds);
  if (s_grad) {
    int32_t* sender_offsets = tape.arena().template allocate_array<int32_t>(static_cast<std::size_t>(s.rows + 1));
    int32_t* edges = tape.arena().template allocate_array<int32_t>(static_cast<std::size_t>(n_edges));
    transpose_csr(graph.senders, s.rows, sender_offsets, edges);
    params.sender_offsets = {sender_offsets, static_cast<std::size_t>(s.rows + 1)};
    params.edges_by_sender = {edges, static_cast<std::size_t>(n_edges)};
  }
  tape.record(OpKind::RotInvAttention, res.out, {q, r, s, res.weights}, params).saved = saved;
  return res;
}

template <class T>
void backward_rot_inv_attention(const Node<T>& node) {
  const auto& [q, r, s, w] = node.in;
  const RiaParams<T>& params = std::get<RiaParams<T>>(node.params);
  const RiaProblem<T> pb = make_problem(params, q, r, s);
  const int64_t EH = static_cast<int64_t>(params.senders.size()) * pb.heads;
  T* ds_edge = s.grad ? backward_scratch<T, kScratchRiaSenders>(params.senders.size() * static_cast<std::size_t>(q.cols))
                     : nullptr;
  ria_backward_receivers_any(pb, node.saved, node.saved + EH, node.saved + 2 * EH, node.out.grad, w.grad,
                             backward_scratch<T, kScratchRiaWeights>(static_cast<std::size_t>(EH)), q.grad, r.grad,
                             ds_edge);
  if (s.grad) {
    const int32_t* sender_offsets = params.sender_offsets.data();
    const int32_t* edges = params.edges_by_sender.data();
    if (pb.dim == 16) ria_backward_senders<T, 16>(pb, sender_offsets, edges, ds_edge, s.grad);
    else ria_backward_senders<T, 0>(pb, sender_offsets, edges, ds_edge, s.grad);
  }
}

#define LAYERSNET_INSTANTIATE(T)                                                                          \
  template RiaResult<T> rot_inv_attention<T>(Tape<T>&, const Var<T>&, const Var<T>&, const Var<T>&,       \
                                             const RiaGraph&, T, T);                                      \
  template void backward_rot_inv_attention<T>(const Node<T>&);
LAYERSNET_INSTANTIATE(float)
LAYERSNET_INSTANTIATE(double)
#undef LAYERSNET_INSTANTIATE

}  // namespace layersnet::ad
