#include "autodiff/ops_graph.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace layersnet::ad {

namespace {

// Below this many scalar operations a kernel runs on one thread (fork/join costs more).
constexpr int64_t kParallelMin = int64_t{1} << 15;
// Column block of the scatter kernels: 32 doubles / floats = 4 / 2 cache lines.
constexpr int64_t kColumnBlock = 32;

// ---- kernels (no tape, no allocation) ---------------------------------------------------

// out[e, :] = x[idx[e], :cols]       x: (M, ·) rows `x_stride` apart, idx: (E), out: (E, cols)
template <class T>
void gather_rows_forward(const T* x, int64_t x_stride, const int32_t* idx, int64_t n_edges, int64_t cols, T* out) {
#pragma omp parallel for schedule(static) if (n_edges * cols > kParallelMin)
  for (int64_t e = 0; e < n_edges; ++e) {
    const T* src = x + int64_t{idx[e]} * x_stride;
    std::copy(src, src + cols, out + e * cols);
  }
}

// out[idx[e], :cols] += x[e, :]       x: (E, cols), idx: (E), out: (M, ·) rows `out_stride` apart
// Parallel over column blocks; each block walks the edges in order, so the sum order of
// every element is the edge order whatever the thread count.
template <class T>
void scatter_add_rows_kernel(const T* x, const int32_t* idx, int64_t n_edges, int64_t cols, T* out,
                             int64_t out_stride) {
  const int64_t n_blocks = (cols + kColumnBlock - 1) / kColumnBlock;
#pragma omp parallel for schedule(static) if (n_edges * cols > kParallelMin && n_blocks > 1)
  for (int64_t b = 0; b < n_blocks; ++b) {
    const int64_t c0 = b * kColumnBlock, c1 = std::min(cols, c0 + kColumnBlock);
    for (int64_t e = 0; e < n_edges; ++e) {
      const T* src = x + e * cols;
      T* dst = out + int64_t{idx[e]} * out_stride;
      for (int64_t c = c0; c < c1; ++c) dst[c] += src[c];
    }
  }
}

// out[k, :] += sum_{e in segment k} x[e, :]     x: (E, C), offsets: (S+1), out: (S, C)
template <class T>
void segment_sum_forward(const T* x, const int32_t* offsets, int64_t n_seg, int64_t cols, T* out) {
#pragma omp parallel for schedule(static) if (int64_t{offsets[n_seg]} * cols > kParallelMin)
  for (int64_t k = 0; k < n_seg; ++k) {
    T* dst = out + k * cols;
    for (int64_t e = offsets[k]; e < offsets[k + 1]; ++e) {
      const T* src = x + e * cols;
      for (int64_t c = 0; c < cols; ++c) dst[c] += src[c];
    }
  }
}

// gx[e, :] += g[k, :] for e in segment k         g: (S, C), gx: (E, C)
template <class T>
void segment_sum_backward(const T* g, const int32_t* offsets, int64_t n_seg, int64_t cols, T* gx) {
#pragma omp parallel for schedule(static) if (int64_t{offsets[n_seg]} * cols > kParallelMin)
  for (int64_t k = 0; k < n_seg; ++k) {
    const T* src = g + k * cols;
    for (int64_t e = offsets[k]; e < offsets[k + 1]; ++e) {
      T* dst = gx + e * cols;
      for (int64_t c = 0; c < cols; ++c) dst[c] += src[c];
    }
  }
}

// a = softmax of z within each segment, per column.   z, a: (E, H), offsets: (S+1)
template <class T>
void segment_softmax_forward(const T* z, const int32_t* offsets, int64_t n_seg, int64_t heads, T* a) {
#pragma omp parallel for schedule(static) if (int64_t{offsets[n_seg]} * heads > kParallelMin)
  for (int64_t k = 0; k < n_seg; ++k) {
    const int64_t e0 = offsets[k], e1 = offsets[k + 1];
    for (int64_t h = 0; h < heads; ++h) {
      T zmax = -std::numeric_limits<T>::infinity();
      for (int64_t e = e0; e < e1; ++e) zmax = std::max(zmax, z[e * heads + h]);
      if (zmax == -std::numeric_limits<T>::infinity()) {  // every logit masked with -inf: all zero
        for (int64_t e = e0; e < e1; ++e) a[e * heads + h] = 0;
        continue;
      }
      T sum = 0;
      for (int64_t e = e0; e < e1; ++e) sum += (a[e * heads + h] = std::exp(z[e * heads + h] - zmax));
      const T inv = T(1) / sum;  // sum >= 1: the maximum contributes exp(0)
      for (int64_t e = e0; e < e1; ++e) a[e * heads + h] *= inv;
    }
  }
}

// gz += a * (g - sum_seg(a * g)), per segment and column.   a, g, gz: (E, H)
template <class T>
void segment_softmax_backward(const T* a, const T* g, const int32_t* offsets, int64_t n_seg, int64_t heads, T* gz) {
#pragma omp parallel for schedule(static) if (int64_t{offsets[n_seg]} * heads > kParallelMin)
  for (int64_t k = 0; k < n_seg; ++k) {
    const int64_t e0 = offsets[k], e1 = offsets[k + 1];
    for (int64_t h = 0; h < heads; ++h) {
      T dot = 0;
      for (int64_t e = e0; e < e1; ++e) dot += a[e * heads + h] * g[e * heads + h];
      for (int64_t e = e0; e < e1; ++e) gz[e * heads + h] += a[e * heads + h] * (g[e * heads + h] - dot);
    }
  }
}

template <class T>
void check_cols(const char* what, const Var<T>& a, const Var<T>& b) {
  LAYERSNET_CHECK(a.cols == b.cols, what << ": column counts differ (" << a.cols << " vs " << b.cols
                                         << "); both inputs need the same width");
}

}  // namespace

void check_csr(const char* what, std::span<const int32_t> offsets, int64_t n_rows) {
  LAYERSNET_CHECK(!offsets.empty() && offsets.front() == 0,
                  what << ": CSR offsets must start with 0 and have S+1 entries");
  for (std::size_t k = 1; k < offsets.size(); ++k)
    LAYERSNET_CHECK(offsets[k] >= offsets[k - 1], what << ": CSR offsets decrease at segment " << k - 1);
  LAYERSNET_CHECK(offsets.back() == n_rows, what << ": CSR offsets end at " << offsets.back() << " but there are "
                                                 << n_rows << " rows; the last offset must equal the row count");
}

void check_indices(const char* what, std::span<const int32_t> idx, int64_t bound) {
  for (std::size_t e = 0; e < idx.size(); ++e)
    LAYERSNET_CHECK(idx[e] >= 0 && idx[e] < bound,
                    what << ": index " << idx[e] << " at position " << e << " is outside [0, " << bound << ")");
}

// ---- gather_rows ------------------------------------------------------------------------
// Node: in[0] = x; RowIndexParams::rows = idx (E), first_col = c0.
template <class T>
Var<T> gather_rows(Tape<T>& tape, const Var<T>& x, std::span<const int32_t> idx, int64_t c0, int64_t c1) {
  check_indices("gather_rows", idx, x.rows);
  LAYERSNET_CHECK(0 <= c0 && c0 <= c1 && c1 <= x.cols,
                  "gather_rows: columns [" << c0 << ", " << c1 << ") are not within the " << x.cols << " of x");
  const auto n = static_cast<int64_t>(idx.size());
  const bool grad = tape.wants_grad({x});
  Var<T> out = tape.new_var(n, c1 - c0, grad);
  gather_rows_forward(x.value + c0, x.cols, idx.data(), n, c1 - c0, out.value);
  if (grad) tape.record(OpKind::GatherRows, out, {x}, RowIndexParams{tape.copy_to_arena(idx), c0});
  return out;
}

template <class T>
Var<T> gather_rows(Tape<T>& tape, const Var<T>& x, std::span<const int32_t> idx) {
  return gather_rows(tape, x, idx, 0, x.cols);
}

template <class T>
void backward_gather_rows(const Node<T>& node) {
  const Var<T>& x = node.in[0];
  const auto& params = std::get<RowIndexParams>(node.params);
  if (x.grad)
    scatter_add_rows_kernel(node.out.grad, params.rows.data(), node.out.rows, node.out.cols, x.grad + params.first_col,
                            x.cols);
}

// ---- scatter_add_rows -------------------------------------------------------------------
// Node: in[0] = x; RowIndexParams::rows = idx (E).
template <class T>
Var<T> scatter_add_rows(Tape<T>& tape, const Var<T>& x, std::span<const int32_t> idx, int64_t n_out) {
  LAYERSNET_CHECK(static_cast<int64_t>(idx.size()) == x.rows,
                  "scatter_add_rows: " << idx.size() << " indices for " << x.rows << " rows; need one per row");
  check_indices("scatter_add_rows", idx, n_out);
  const bool grad = tape.wants_grad({x});
  Var<T> out = tape.zeros(n_out, x.cols, grad);
  scatter_add_rows_kernel(x.value, idx.data(), x.rows, x.cols, out.value, x.cols);
  if (grad) tape.record(OpKind::ScatterAddRows, out, {x}, RowIndexParams{tape.copy_to_arena(idx)});
  return out;
}

template <class T>
void backward_scatter_add_rows(const Node<T>& node) {
  const Var<T>& x = node.in[0];
  if (!x.grad) return;
  const int64_t cols = x.cols;
  const int32_t* idx = std::get<RowIndexParams>(node.params).rows.data();
#pragma omp parallel for schedule(static) if (x.rows * cols > kParallelMin)
  for (int64_t e = 0; e < x.rows; ++e) {
    const T* src = node.out.grad + int64_t{idx[e]} * cols;
    T* dst = x.grad + e * cols;
    for (int64_t c = 0; c < cols; ++c) dst[c] += src[c];
  }
}

// ---- segment_sum ------------------------------------------------------------------------
// Node: in[0] = x; SegmentParams::offsets (S+1).
template <class T>
Var<T> segment_sum(Tape<T>& tape, const Var<T>& x, std::span<const int32_t> offsets) {
  check_csr("segment_sum", offsets, x.rows);
  const auto n_seg = static_cast<int64_t>(offsets.size()) - 1;
  const bool grad = tape.wants_grad({x});
  Var<T> out = tape.zeros(n_seg, x.cols, grad);
  segment_sum_forward(x.value, offsets.data(), n_seg, x.cols, out.value);
  if (grad) tape.record(OpKind::SegmentSum, out, {x}, SegmentParams{tape.copy_to_arena(offsets)});
  return out;
}

template <class T>
void backward_segment_sum(const Node<T>& node) {
  const Var<T>& x = node.in[0];
  if (x.grad)
    segment_sum_backward(node.out.grad, std::get<SegmentParams>(node.params).offsets.data(), node.out.rows, x.cols,
                         x.grad);
}

// ---- segment_softmax --------------------------------------------------------------------
// Node: in[0] = logits; SegmentParams::offsets (S+1); the output values are the saved softmax.
template <class T>
Var<T> segment_softmax(Tape<T>& tape, const Var<T>& logits, std::span<const int32_t> offsets) {
  check_csr("segment_softmax", offsets, logits.rows);
  const auto n_seg = static_cast<int64_t>(offsets.size()) - 1;
  const bool grad = tape.wants_grad({logits});
  Var<T> out = tape.new_var(logits.rows, logits.cols, grad);
  segment_softmax_forward(logits.value, offsets.data(), n_seg, logits.cols, out.value);
  if (grad) tape.record(OpKind::SegmentSoftmax, out, {logits}, SegmentParams{tape.copy_to_arena(offsets)});
  return out;
}

template <class T>
void backward_segment_softmax(const Node<T>& node) {
  const Var<T>& z = node.in[0];
  if (!z.grad) return;
  const std::span<const int32_t> offsets = std::get<SegmentParams>(node.params).offsets;
  segment_softmax_backward(node.out.value, node.out.grad, offsets.data(), static_cast<int64_t>(offsets.size()) - 1,
                           z.cols, z.grad);
}

// ---- concat_rows ------------------------------------------------------------------------
// Node: in[0] = a, in[1] = b.
template <class T>
Var<T> concat_rows(Tape<T>& tape, const Var<T>& a, const Var<T>& b) {
  check_cols("concat_rows", a, b);
  const bool grad = tape.wants_grad({a, b});
  Var<T> out = tape.new_var(a.rows + b.rows, a.cols, grad);
  std::copy(a.value, a.value + a.size(), out.value);
  std::copy(b.value, b.value + b.size(), out.value + a.size());
  if (grad) tape.record(OpKind::ConcatRows, out, {a, b});
  return out;
}

template <class T>
void backward_concat_rows(const Node<T>& node) {
  const Var<T>& a = node.in[0];
  const Var<T>& b = node.in[1];
  const T* g = node.out.grad;
  if (a.grad)
    for (int64_t k = 0; k < a.size(); ++k) a.grad[k] += g[k];
  if (b.grad)
    for (int64_t k = 0; k < b.size(); ++k) b.grad[k] += g[a.size() + k];
}

#define LAYERSNET_INSTANTIATE(T)                                                                \
  template Var<T> gather_rows<T>(Tape<T>&, const Var<T>&, std::span<const int32_t>);           \
  template Var<T> gather_rows<T>(Tape<T>&, const Var<T>&, std::span<const int32_t>, int64_t, int64_t); \
  template Var<T> scatter_add_rows<T>(Tape<T>&, const Var<T>&, std::span<const int32_t>, int64_t); \
  template Var<T> segment_sum<T>(Tape<T>&, const Var<T>&, std::span<const int32_t>);           \
  template Var<T> segment_softmax<T>(Tape<T>&, const Var<T>&, std::span<const int32_t>);       \
  template Var<T> concat_rows<T>(Tape<T>&, const Var<T>&, const Var<T>&);                      \
  template void backward_gather_rows<T>(const Node<T>&);                                       \
  template void backward_scatter_add_rows<T>(const Node<T>&);                                  \
  template void backward_segment_sum<T>(const Node<T>&);                                       \
  template void backward_segment_softmax<T>(const Node<T>&);                                   \
  template void backward_concat_rows<T>(const Node<T>&);
LAYERSNET_INSTANTIATE(float)
LAYERSNET_INSTANTIATE(double)
#undef LAYERSNET_INSTANTIATE

}  // namespace layersnet::ad
