#pragma once
// Dense ops on the tape. Shapes: N rows, C columns (Cin / Cout for linear layers).
// Each op has plain kernels (`*_forward` / `*_backward` in ops_dense.cpp, no tape, no
// allocation) and a wrapper declared here that computes the output into the tape's arena
// and records a node when a gradient is wanted.
//
// Broadcasting (add, sub, mul, div): the second operand b may be (N, C), (1, C) [one row
// repeated], (N, 1) [one column repeated] or (1, 1); the output has a's shape.
//
// An "empty" Var (value == nullptr, 0 x 0, e.g. `Var<T>{}`) stands for an absent optional
// input (linear without bias, layer_norm without affine parameters).
//
// Large tensors are processed by OpenMP over blocks of rows (autodiff/row_blocks.h);
// reductions over rows sum fixed-size blocks in a fixed order, so results do not depend
// on the thread count. Ops must not be called from inside an OpenMP parallel region
// expecting parallelism: they then run serially (never nested).
#include "autodiff/tape.h"

#include <initializer_list>
#include <span>
#include <type_traits>

namespace layersnet::ad {

// Scalar parameters are std::type_identity_t<T>, so `scale(tape, x, 0.5)` works on a
// float tape.

// ---- linear algebra ----------------------------------------------------------------------

// out = x Wᵀ + b (torch.nn.Linear). x: (N, Cin); W: (Cout, Cin) [torch layout];
// b: (1, Cout) or empty (no bias). out: (N, Cout).
// Rows are cut into up to 16 chunks (a count fixed by N), one single-threaded Eigen GEMM
// per chunk into output rows pre-filled with the bias (so the bias costs no extra pass),
// chunks spread over the OpenMP threads. Backward: dx += dy W per chunk; dW += dyᵀ x and
// db += column sums of dy as per-chunk partials added in chunk order, so every gradient
// is bit-identical for any thread count.
// With tape.matmul_precision() == kBFloat16 (inference only: throws if the tape records),
// products with Cin >= 16 and Cout >= 16 run in bfloat16 (autodiff/bf16_gemm.h); narrower
// ones (the model's transposes by an identity, its 3-D geometric maps) stay float: bf16
// would make them lossy and gains nothing there.
template <class T>
Var<T> linear(Tape<T>& tape, const Var<T>& x, const Var<T>& W, const Var<T>& b = {});

// out = residual + x Wᵀ + b: a linear layer with a residual connection, in one pass (the
// residual and the bias fill the output rows the GEMM accumulates into, so the sum costs no
// separate Add over the output). residual: (N, Cout), not empty; other shapes as linear.
// Backward as linear, plus d residual += dy. Recorded as a Linear node.
template <class T>
Var<T> linear_add(Tape<T>& tape, const Var<T>& x, const Var<T>& W, const Var<T>& b, const Var<T>& residual);

// out = max(x Wᵀ + b, 0): linear followed by ReLU, fused (the FFN/MLP hidden layers).
// Saves the separate ReLU tensor and its memory passes: the max is taken on each row chunk
// right after its GEMM, and backward masks dy chunk by chunk just before its GEMMs.
// Shapes as linear.
template <class T>
Var<T> linear_relu(Tape<T>& tape, const Var<T>& x, const Var<T>& W, const Var<T>& b = {});

// A chain of linear layers with a ReLU after each but the last (and after the last too with
// final_relu): h_0 = x, h_i = ReLU(h_{i-1} W_iᵀ + b_i), out = h_k. x: (N, Cin);
// weights[i]: (C_{i+1}, C_i) with C_0 = Cin; biases: one per layer, (1, C_{i+1}) or empty;
// out: (N, C_k). The same function as linear / linear_relu layer by layer, computed a block
// of rows at a time through every layer, so that the hidden rows of a block stay in cache
// (an inference forward writes no hidden activation to memory; a recording one saves them
// for backward). Rows are cut into chunks as in linear, so results do not depend on the
// thread count. bf16 matmul precision applies per layer as in linear.
template <class T>
Var<T> mlp(Tape<T>& tape, const Var<T>& x, std::span<const Var<T>> weights, std::span<const Var<T>> biases,
           bool final_relu);

// ---- elementwise, with broadcasting of b ---------------------------------------------------

// out = a + b. a: (N, C); b: (N, C), (1, C), (N, 1) or (1, 1).
template <class T>
Var<T> add(Tape<T>& tape, const Var<T>& a, const Var<T>& b);
// out = a - b. Shapes as add.
template <class T>
Var<T> sub(Tape<T>& tape, const Var<T>& a, const Var<T>& b);
// out = a * b (elementwise). Shapes as add.
template <class T>
Var<T> mul(Tape<T>& tape, const Var<T>& a, const Var<T>& b);
// out = a / b (elementwise). Shapes as add. b must not be 0 (no guard: IEEE semantics).
template <class T>
Var<T> div(Tape<T>& tape, const Var<T>& a, const Var<T>& b);

// out = c * x for a constant c (not differentiated). x, out: (N, C).
template <class T>
Var<T> scale(Tape<T>& tape, const Var<T>& x, std::type_identity_t<T> c);

// out = max(x, 0). x, out: (N, C). The derivative at exactly 0 is taken as 0.
template <class T>
Var<T> relu(Tape<T>& tape, const Var<T>& x);

// out = min(x - thr, 0)² elementwise (one-sided quadratic penalty, e.g. the collision
// loss's min(d - eps, 0)²). x, out: (N, C); thr a constant. C¹ at x = thr (gradient 0).
template <class T>
Var<T> hinge_sq(Tape<T>& tape, const Var<T>& x, std::type_identity_t<T> thr);

// ---- normalisation -----------------------------------------------------------------------

// LayerNorm over the columns of each row (torch.nn.LayerNorm(C)):
//   out = (x - mean) * rstd * gamma + beta,  rstd = 1 / sqrt(var + eps), var biased.
// x, out: (N, C); gamma, beta: (1, C) or both empty (no affine transform).
// Saves mean and rstd per row for backward. A constant row gives out = beta and a
// finite gradient (rstd = 1/sqrt(eps)).
template <class T>
Var<T> layer_norm(Tape<T>& tape, const Var<T>& x, const Var<T>& gamma, const Var<T>& beta,
                  std::type_identity_t<T> eps = T(1e-5));

// ---- columns -----------------------------------------------------------------------------

// out = [x_0 | x_1 | ...] side by side. Every x_k: (N, C_k); out: (N, Σ C_k).
template <class T>
Var<T> concat_cols(Tape<T>& tape, std::span<const Var<T>> inputs);
template <class T>
Var<T> concat_cols(Tape<T>& tape, std::initializer_list<Var<T>> inputs) {
  return concat_cols(tape, std::span<const Var<T>>(inputs.begin(), inputs.size()));
}

// out = x[:, c0:c1]. x: (N, C); out: (N, c1 - c0); 0 <= c0 <= c1 <= C.
// (Split = several slices; each slice's backward adds into its own columns.)
template <class T>
Var<T> slice_cols(Tape<T>& tape, const Var<T>& x, int64_t c0, int64_t c1);

// ---- reductions --------------------------------------------------------------------------

// Sum / mean of every entry. x: (N, C); out: (1, 1). The mean of an empty x is 0.
template <class T>
Var<T> sum_all(Tape<T>& tape, const Var<T>& x);
template <class T>
Var<T> mean_all(Tape<T>& tape, const Var<T>& x);

// Per-column sum / mean over the rows. x: (N, C); out: (1, C).
template <class T>
Var<T> col_sum(Tape<T>& tape, const Var<T>& x);
template <class T>
Var<T> col_mean(Tape<T>& tape, const Var<T>& x);

// Per-row sum / mean over the columns. x: (N, C); out: (N, 1).
template <class T>
Var<T> row_sum(Tape<T>& tape, const Var<T>& x);
template <class T>
Var<T> row_mean(Tape<T>& tape, const Var<T>& x);

// ---- losses ------------------------------------------------------------------------------

// Per-row squared distance: out_i = Σ_c (a_ic - b_ic)². a, b: (N, C); out: (N, 1).
// The official L2Loss Σ_v ‖x̂_v − x_v‖² / N is mean_all(squared_error(pred, target)).
template <class T>
Var<T> squared_error(Tape<T>& tape, const Var<T>& a, const Var<T>& b);

}  // namespace layersnet::ad
