#pragma once
// Graph ops on the tape: moving rows along index lists and reducing over neighbour segments.
//
// Dimension letters: M source rows, E edges (index entries), S segments, C columns.
// Index lists are int32 (row numbers); segments are CSR offsets: segment k holds rows
// [offsets[k], offsets[k+1]), offsets has S+1 entries, offsets[0] = 0, non-decreasing, and
// offsets[S] = E. Empty segments are allowed everywhere. Indices are range-checked (always).
//
// Determinism: every reduction sums in a fixed order that does not depend on the thread
// count (scatter-adds are parallelised over column blocks, each block walks the edges in
// order; segment reductions are parallelised over segments). No atomics.
//
// Geometry ops (norms, cross products, rotations) are in ops_geometry.h; the fused
// Rotation Invariant Attention is in ops_attention.h, the block linear solve in ops_solve.h.
// This header includes them.
#include "autodiff/tape.h"

#include <cstdint>
#include <span>

namespace layersnet::ad {

// out[e, :] = x[idx[e], :].                       x: (M, C), idx: (E) in [0, M) -> (E, C)
// Backward scatter-adds into x (rows used twice get both contributions).
template <class T>
Var<T> gather_rows(Tape<T>& tape, const Var<T>& x, std::span<const int32_t> idx);
// out[e, :] = x[idx[e], c0:c1]: the gather of a column range, without the full rows' copy.
// x: (M, C), 0 <= c0 <= c1 <= C -> (E, c1 - c0). Backward scatter-adds into those columns.
template <class T>
Var<T> gather_rows(Tape<T>& tape, const Var<T>& x, std::span<const int32_t> idx, int64_t c0, int64_t c1);

// out[k, :] = sum_{e : idx[e] = k} x[e, :].     x: (E, C), idx: (E) in [0, n_out) -> (n_out, C)
// Rows no edge points to are zero. Sums in edge order.
template <class T>
Var<T> scatter_add_rows(Tape<T>& tape, const Var<T>& x, std::span<const int32_t> idx, int64_t n_out);

// out[k, :] = sum_{e in segment k} x[e, :].      x: (E, C), offsets: (S+1) CSR -> (S, C)
// The sorted (CSR) form of scatter_add_rows; an empty segment gives a zero row.
template <class T>
Var<T> segment_sum(Tape<T>& tape, const Var<T>& x, std::span<const int32_t> offsets);

// Softmax over the rows of each segment, independently per column.
// logits: (E, H), offsets: (S+1) CSR -> (E, H); each column of a non-empty segment sums to 1.
// The segment maximum is subtracted first, so logits of +-80 (or +-1e4) do not overflow.
// A logit of -inf gets weight 0 (masking); a column whose logits are all -inf gets all zeros.
template <class T>
Var<T> segment_softmax(Tape<T>& tape, const Var<T>& logits, std::span<const int32_t> offsets);

// Row concatenation [a; b].                     a: (M1, C), b: (M2, C) -> (M1 + M2, C)
// (e.g. encoder tokens = [patch tokens; attribute tokens], senders = [patches; inter]).
template <class T>
Var<T> concat_rows(Tape<T>& tape, const Var<T>& a, const Var<T>& b);

// The same tensor seen as (rows, cols), rows * cols = x.rows * x.cols: a zero-copy alias of
// the row-major values AND gradient, so no node is needed (e.g. the decoder's (N, 12) relative
// states as (4N, 3) 3-vectors for rotate3).
template <class T>
Var<T> reshape(const Var<T>& x, int64_t rows, int64_t cols) {
  LAYERSNET_CHECK(rows >= 0 && cols >= 0 && rows * cols == x.rows * x.cols,
                  "reshape: (" << x.rows << ", " << x.cols << ") has " << x.size() << " entries, not (" << rows
                               << ", " << cols << ")");
  Var<T> v = x;
  v.rows = rows;
  v.cols = cols;
  return v;
}

// Throws unless offsets is a valid CSR over n_rows rows (offsets[0] = 0, non-decreasing,
// last = n_rows). `what` names the caller for the message.
void check_csr(const char* what, std::span<const int32_t> offsets, int64_t n_rows);
// Throws unless every idx[e] is in [0, bound).
void check_indices(const char* what, std::span<const int32_t> idx, int64_t bound);

}  // namespace layersnet::ad

#include "autodiff/ops_attention.h"
#include "autodiff/ops_geometry.h"
#include "autodiff/ops_solve.h"
