#pragma once
// Fused Rotation Invariant Attention (paper eq. 5-7; official attention.py / norm_func.py)
// over sparse neighbour lists.
//
// Dimension letters: P receivers (patches), M senders, E edges, H heads, D head width.
// q, r: (P, H*D); s: (M, H*D); head h uses columns [h*D, (h+1)*D).
// Edge e = (i, j) belongs to receiver i (CSR `offsets`, (P+1)) and reads sender row
// j = senders[e]. For every head h and edge e that head h attends to:
//   rho_e = sqrt(||r_i - s_j||^2 + eps^2)                  (smoothed distance, see below)
//   z_e   = scale * (q_i . s_j + q_i . r_i) / (rho_e / 2)  (logit, eq. 7 with the official /2)
//   a_e   = softmax of z over the edges of receiver i that head h attends to
//   w_e   = a_e / rho_e                                    ("a' = a / ||r - s||")
//   out_i = sum_e [kind_e in message_kinds] * w_e * (s_j + r_i)
// Outputs: out (P, H*D) and the edge weights w (E, H) (0 where a head does not attend), so a
// model can build messages of its own from w (the official inter-neighbour messages:
// gather the inter edges' w, multiply by psi(phi(R)(r + hs)) rotated back, segment_sum).
// Both outputs are differentiable; gradients flow to q, r and s.
//
// Head masks: each edge has a kind (0..31) and head h attends to the kinds whose bits are set
// in head_kinds[h]; only edges whose kind is in message_kinds add the (s + r) message. The
// caller owns the meaning of the kinds (LayersNet's world / mesh / inter table is in
// model/layersnet.cpp). A receiver with no attended edge for a head gets zero output (and
// zero gradient) for that head.
//
// Deviation from the official code (quirk 8): the official logit divides by
// ||r - s||/2 + 1e-7 and the weight by ||r - s|| with no eps, which is infinite at r = s and
// has a 0/0 gradient there. Here both use rho = sqrt(||r - s||^2 + eps^2): for
// ||r - s|| >> eps the two agree to ~eps/||r - s|| relative (1e-7 at unit distance), and at
// r = s everything stays finite (w <= 1/eps) with a gradient defined everywhere.
//
// Threads: parallel over receivers (receiver-owned writes to out, w, dq, dr); the sender
// gradient is reduced through a transposed CSR in edge order, so results do not depend on
// the thread count.
#include "autodiff/tape.h"

#include <cstdint>
#include <span>

namespace layersnet::ad {

struct RiaGraph {
  std::span<const int32_t> offsets;      // (P+1) CSR over receivers
  std::span<const int32_t> senders;      // (E) sender row per edge, in [0, M)
  std::span<const int32_t> kinds;        // (E) edge kind per edge, in [0, 32)
  std::span<const uint32_t> head_kinds;  // (H) bit k set: head h attends to kind k
  uint32_t message_kinds = ~0u;          // bit k set: kind k edges add w * (s + r) to out
};

template <class T>
struct RiaResult {
  Var<T> out;      // (P, H*D)
  Var<T> weights;  // (E, H): a / rho
};

// scale: the official 1/sqrt(D) (16^-0.5). eps: the distance smoothing above (official 1e-7).
template <class T>
RiaResult<T> rot_inv_attention(Tape<T>& tape, const Var<T>& q, const Var<T>& r, const Var<T>& s,
                               const RiaGraph& graph, T scale, T eps = T(1e-7));

}  // namespace layersnet::ad
