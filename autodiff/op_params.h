#pragma once
// What an op keeps on its tape node for backward besides its inputs, output and saved
// intermediates: one named struct per op kind that needs any (ops without parameters keep
// std::monostate). Arrays are views into the tape's arena: the caller's vectors may die
// before backward.
#include "autodiff/var.h"

#include <array>
#include <cstdint>
#include <span>
#include <variant>

namespace layersnet::ad {

// Scale: out = factor * x.
template <class T>
struct ScaleParams {
  T factor;
};

// HingeSq: out = min(x - threshold, 0)².
template <class T>
struct HingeSqParams {
  T threshold;
};

// SumAll, ColSum, RowSum: out = factor * sum; factor is 1 for sums, 1 / count for means.
template <class T>
struct ReduceParams {
  T factor;
};

// ConcatCols: every input, in column order.
template <class T>
struct ConcatColsParams {
  std::span<const Var<T>> inputs;
};

// Mlp: the layers' weights (Cout_i, Cin_i) and biases (1, Cout_i) (empty Vars: no bias), and
// whether the last layer is followed by a ReLU too.
template <class T>
struct MlpParams {
  std::span<const Var<T>> weights, biases;
  bool final_relu;
};

// SliceCols: out = x[:, first_col : first_col + out.cols].
struct SliceColsParams {
  int64_t first_col;
};

// GatherRows: the source row of each output row, and the first source column it copies.
// ScatterAddRows: the output row of each input row (first_col 0).
struct RowIndexParams {
  std::span<const int32_t> rows;
  int64_t first_col = 0;
};

// SegmentSum, SegmentSoftmax: CSR offsets (S+1) over the input rows.
struct SegmentParams {
  std::span<const int32_t> offsets;
};

// RowNormalize: rows shorter than eps are divided by eps.
template <class T>
struct RowNormalizeParams {
  T eps;
};

// Rotate3, RotMapApply: apply the transposed rotation.
struct RotationParams {
  bool transpose;
};

// RotInvAttention (autodiff/ops_attention.h): the neighbour graph and head masks of the
// forward, plus the edges grouped by sender for the sender gradient.
template <class T>
struct RiaParams {
  std::span<const int32_t> offsets;      // (P+1) CSR over receivers
  std::span<const int32_t> senders;      // (E) sender row per edge
  std::span<const int32_t> kinds;        // (E) edge kind per edge
  std::span<const uint32_t> head_kinds;  // (H) bit k set: head h attends to kind k
  uint32_t message_kinds;                // bit k set: kind k edges add w * (s + r) to out
  int64_t head_dim;                      // D
  T scale, eps;
  // CSR over senders (M+1) and the edge ids of each sender, ascending; empty when s needs
  // no gradient.
  std::span<const int32_t> sender_offsets;
  std::span<const int32_t> edges_by_sender;
};

// BlockSpdSolve (autodiff/ops_solve.h): a symmetric positive-definite matrix A of 3×3 blocks,
// a scale per block row and the solver's limits.
template <class T>
struct BlockSpd {
  std::span<const int32_t> offsets;  // (N+1) CSR over block rows
  std::span<const int32_t> columns;  // (nnz) block column of each block, in [0, N)
  std::span<const T> blocks;         // (nnz · 9) row-major 3×3 blocks; A must be symmetric
  std::span<const T> scale;          // (N) s
  int iterations = 60;               // conjugate-gradient iterations at most
  T tolerance = T(1e-6);             // stop when the preconditioned residual is this fraction of the start's
};

// VertexNormals (autodiff/ops_cloth.h): the faces (F · 3).
struct FaceParams {
  std::span<const int32_t> faces;
};

// SpringEnergy: each spring's ends (E) and its rest length and half stiffness (E).
template <class T>
struct SpringParams {
  std::span<const int32_t> i, j;
  std::span<const T> rest, half_k;
};

// DihedralAlignment: each hinge's corners i, j, a, p, q, b (H each) and its weights (H).
template <class T>
struct DihedralParams {
  std::array<std::span<const int32_t>, 6> corners;
  std::span<const T> k_cos, k_sin;
};

template <class T>
using OpParams = std::variant<std::monostate, ScaleParams<T>, HingeSqParams<T>, ReduceParams<T>, ConcatColsParams<T>,
                              MlpParams<T>, SliceColsParams, RowIndexParams, SegmentParams, RowNormalizeParams<T>, RotationParams,
                              RiaParams<T>, BlockSpd<T>, FaceParams, SpringParams<T>, DihedralParams<T>>;

}  // namespace layersnet::ad
