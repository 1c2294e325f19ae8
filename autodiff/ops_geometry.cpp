#include "autodiff/ops_geometry.h"

#include "autodiff/row_blocks.h"

#include <algorithm>
#include <cmath>

namespace layersnet::ad {

namespace {

constexpr int64_t kParallelMin = int64_t{1} << 15;

// ---- kernels (no tape, no allocation) ---------------------------------------------------

// y[n] = ||x[n]||                           x: (N, C), y: (N)
template <class T>
void row_norm_forward(const T* x, int64_t rows, int64_t cols, T* y) {
#pragma omp parallel for schedule(static) if (rows * cols > kParallelMin)
  for (int64_t n = 0; n < rows; ++n) {
    T sq = 0;
    for (int64_t c = 0; c < cols; ++c) sq += x[n * cols + c] * x[n * cols + c];
    y[n] = std::sqrt(sq);
  }
}

// gx[n] += g[n] x[n] / y[n]  (0 where y[n] == 0)
template <class T>
void row_norm_backward(const T* x, const T* y, const T* g, int64_t rows, int64_t cols, T* gx) {
#pragma omp parallel for schedule(static) if (rows * cols > kParallelMin)
  for (int64_t n = 0; n < rows; ++n) {
    if (y[n] == T(0)) continue;
    const T k = g[n] / y[n];
    for (int64_t c = 0; c < cols; ++c) gx[n * cols + c] += k * x[n * cols + c];
  }
}

// y[n] = x[n] / m[n], m[n] = max(||x[n]||, eps); m is saved for backward.
template <class T>
void row_normalize_forward(const T* x, int64_t rows, int64_t cols, T eps, T* y, T* m) {
#pragma omp parallel for schedule(static) if (rows * cols > kParallelMin)
  for (int64_t n = 0; n < rows; ++n) {
    T sq = 0;
    for (int64_t c = 0; c < cols; ++c) sq += x[n * cols + c] * x[n * cols + c];
    m[n] = std::max(std::sqrt(sq), eps);
    const T inv = T(1) / m[n];
    for (int64_t c = 0; c < cols; ++c) y[n * cols + c] = x[n * cols + c] * inv;
  }
}

// Where ||x|| > eps: gx += (g - y (y.g)) / ||x||; else (constant divisor): gx += g / eps.
template <class T>
void row_normalize_backward(const T* y, const T* m, const T* g, int64_t rows, int64_t cols, T eps, T* gx) {
#pragma omp parallel for schedule(static) if (rows * cols > kParallelMin)
  for (int64_t n = 0; n < rows; ++n) {
    const T* yn = y + n * cols;
    const T* gn = g + n * cols;
    T dot = 0;
    if (m[n] > eps)
      for (int64_t c = 0; c < cols; ++c) dot += yn[c] * gn[c];
    const T inv = T(1) / m[n];
    for (int64_t c = 0; c < cols; ++c) gx[n * cols + c] += (gn[c] - yn[c] * dot) * inv;
  }
}

template <class T>
inline void cross(const T* a, const T* b, T* out) {
  out[0] = a[1] * b[2] - a[2] * b[1];
  out[1] = a[2] * b[0] - a[0] * b[2];
  out[2] = a[0] * b[1] - a[1] * b[0];
}

// out = R v (or R^T v) for one row; R row-major 3x3.
template <class T>
inline void mat3_apply(const T* R, const T* v, bool transpose, T* out) {
  for (int i = 0; i < 3; ++i)
    out[i] = transpose ? R[i] * v[0] + R[3 + i] * v[1] + R[6 + i] * v[2]
                       : R[3 * i] * v[0] + R[3 * i + 1] * v[1] + R[3 * i + 2] * v[2];
}

// For out = R v:   gR[i][j] += g_i v_j, gv += R^T g.
// For out = R^T v: gR[i][j] += v_i g_j, gv += R g.
template <class T>
inline void mat3_apply_backward(const T* R, const T* v, const T* g, bool transpose, T* gR, T* gv) {
  if (gR)
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) gR[3 * i + j] += transpose ? v[i] * g[j] : g[i] * v[j];
  if (gv) {
    T tmp[3];
    mat3_apply(R, g, !transpose, tmp);
    for (int i = 0; i < 3; ++i) gv[i] += tmp[i];
  }
}

template <class T>
void check_shape(const char* what, const Var<T>& v, int64_t rows, int64_t cols) {
  LAYERSNET_CHECK(v.rows == rows && v.cols == cols, what << ": expected (" << rows << ", " << cols << "), got ("
                                                         << v.rows << ", " << v.cols << ")");
}

}  // namespace

// ---- row_norm ---------------------------------------------------------------------------
// Node: in[0] = x; the output holds the norms.
template <class T>
Var<T> row_norm(Tape<T>& tape, const Var<T>& x) {
  const bool grad = tape.wants_grad({x});
  Var<T> out = tape.new_var(x.rows, 1, grad);
  row_norm_forward(x.value, x.rows, x.cols, out.value);
  if (grad) tape.record(OpKind::RowNorm, out, {x});
  return out;
}

template <class T>
void backward_row_norm(const Node<T>& node) {
  const Var<T>& x = node.in[0];
  if (x.grad) row_norm_backward(x.value, node.out.value, node.out.grad, x.rows, x.cols, x.grad);
}

// ---- row_normalize ----------------------------------------------------------------------
// Node: in[0] = x; RowNormalizeParams::eps; saved = max(||x[n]||, eps) (N).
template <class T>
Var<T> row_normalize(Tape<T>& tape, const Var<T>& x, T eps) {
  LAYERSNET_CHECK(eps > T(0), "row_normalize: eps must be positive, got " << eps);
  const bool grad = tape.wants_grad({x});
  Var<T> out = tape.new_var(x.rows, x.cols, grad);
  T* m = tape.scratch(static_cast<std::size_t>(x.rows));
  row_normalize_forward(x.value, x.rows, x.cols, eps, out.value, m);
  if (grad) tape.record(OpKind::RowNormalize, out, {x}, RowNormalizeParams<T>{eps}).saved = m;
  return out;
}

template <class T>
void backward_row_normalize(const Node<T>& node) {
  const Var<T>& x = node.in[0];
  if (x.grad)
    row_normalize_backward(node.out.value, node.saved, node.out.grad, x.rows, x.cols,
                           std::get<RowNormalizeParams<T>>(node.params).eps, x.grad);
}

// ---- cross3 -----------------------------------------------------------------------------
// Node: in[0] = a, in[1] = b.
template <class T>
Var<T> cross3(Tape<T>& tape, const Var<T>& a, const Var<T>& b) {
  check_shape("cross3 a", a, a.rows, 3);
  check_shape("cross3 b", b, a.rows, 3);
  const bool grad = tape.wants_grad({a, b});
  Var<T> out = tape.new_var(a.rows, 3, grad);
#pragma omp parallel for schedule(static) if (a.rows * 9 > kParallelMin)
  for (int64_t n = 0; n < a.rows; ++n) cross(a.value + 3 * n, b.value + 3 * n, out.value + 3 * n);
  if (grad) tape.record(OpKind::Cross3, out, {a, b});
  return out;
}

template <class T>
void backward_cross3(const Node<T>& node) {
  const Var<T>& a = node.in[0];
  const Var<T>& b = node.in[1];
  // d<g, a x b> = <da, b x g> + <db, g x a>
#pragma omp parallel for schedule(static) if (a.rows * 18 > kParallelMin)
  for (int64_t n = 0; n < a.rows; ++n) {
    const T* g = node.out.grad + 3 * n;
    T tmp[3];
    if (a.grad) {
      cross(b.value + 3 * n, g, tmp);
      for (int c = 0; c < 3; ++c) a.grad[3 * n + c] += tmp[c];
    }
    if (b.grad) {
      cross(g, a.value + 3 * n, tmp);
      for (int c = 0; c < 3; ++c) b.grad[3 * n + c] += tmp[c];
    }
  }
}

// ---- rotate3 ----------------------------------------------------------------------------
// Node: in[0] = R, in[1] = v; RotationParams::transpose.
template <class T>
Var<T> rotate3(Tape<T>& tape, const Var<T>& R, const Var<T>& v, bool transpose) {
  check_shape("rotate3 v", v, v.rows, 3);
  check_shape("rotate3 R (one row-major 3x3 per row of v)", R, v.rows, 9);
  const bool grad = tape.wants_grad({R, v});
  Var<T> out = tape.new_var(v.rows, 3, grad);
#pragma omp parallel for schedule(static) if (v.rows * 15 > kParallelMin)
  for (int64_t n = 0; n < v.rows; ++n) mat3_apply(R.value + 9 * n, v.value + 3 * n, transpose, out.value + 3 * n);
  if (grad) tape.record(OpKind::Rotate3, out, {R, v}, RotationParams{transpose});
  return out;
}

template <class T>
void backward_rotate3(const Node<T>& node) {
  const Var<T>& R = node.in[0];
  const Var<T>& v = node.in[1];
  const bool transpose = std::get<RotationParams>(node.params).transpose;
#pragma omp parallel for schedule(static) if (v.rows * 36 > kParallelMin)
  for (int64_t n = 0; n < v.rows; ++n)
    mat3_apply_backward(R.value + 9 * n, v.value + 3 * n, node.out.grad + 3 * n, transpose,
                        R.grad ? R.grad + 9 * n : nullptr, v.grad ? v.grad + 3 * n : nullptr);
}

// ---- rot_map_apply ----------------------------------------------------------------------
// Node: in[0] = W, in[1] = R, in[2] = v; RotationParams::transpose;
// saved = [t = v W (N, 3) | u = rows R t (N, 3)]; backward's dU, dT (N, 3) are backward scratch.
template <class T>
Var<T> rot_map_apply(Tape<T>& tape, const Var<T>& W, const Var<T>& R, const Var<T>& v, bool transpose) {
  check_shape("rot_map_apply W (d, 3)", W, W.rows, 3);
  check_shape("rot_map_apply v (N, d) with d = rows of W", v, v.rows, W.rows);
  check_shape("rot_map_apply R (one row-major 3x3 per row of v)", R, v.rows, 9);
  const int64_t n_rows = v.rows;
  const bool grad = tape.wants_grad({W, R, v});
  Var<T> out = tape.new_var(n_rows, W.rows, grad);
  T* saved = tape.scratch(static_cast<std::size_t>(6 * n_rows));
  // Row by row: t = Wᵀ v (three dot products), u = R t, out = W u (three scaled columns of W).
  // Eigen's GEMM packed its operands for these width-3 products and ran them on one thread: the
  // forward took twice as long. (The backward's GEMMs were not slower than the same by rows.)
  const int64_t d = W.rows;
  std::vector<T> columns(static_cast<std::size_t>(3 * d));  // W's columns, each contiguous
  for (int64_t k = 0; k < d; ++k)
    for (int c = 0; c < 3; ++c) columns[c * d + k] = W.value[3 * k + c];
  using Column = Eigen::Map<const Eigen::Array<T, Eigen::Dynamic, 1>>;
  const Column w0(columns.data(), d), w1(columns.data() + d, d), w2(columns.data() + 2 * d, d);
  for_row_blocks(n_rows, d, [&](int64_t r0, int64_t n) {
    for (int64_t row = r0; row < r0 + n; ++row) {
      const Column vr(v.value + row * d, d);
      T* tr = saved + 3 * row;
      T* ur = saved + 3 * (n_rows + row);
      tr[0] = (vr * w0).sum(), tr[1] = (vr * w1).sum(), tr[2] = (vr * w2).sum();
      mat3_apply(R.value + 9 * row, tr, transpose, ur);
      Eigen::Map<Eigen::Array<T, Eigen::Dynamic, 1>>(out.value + row * d, d) = ur[0] * w0 + ur[1] * w1 + ur[2] * w2;
    }
  });
  if (grad) tape.record(OpKind::RotMapApply, out, {W, R, v}, RotationParams{transpose}).saved = saved;
  return out;
}

template <class T>
void backward_rot_map_apply(const Node<T>& node) {
  const Var<T>& W = node.in[0];
  const Var<T>& R = node.in[1];
  const Var<T>& v = node.in[2];
  const bool transpose = std::get<RotationParams>(node.params).transpose;
  const int64_t n_rows = v.rows;
  T* saved = node.saved;
  ConstMatMap<T> t(saved, n_rows, 3), u(saved + 3 * n_rows, n_rows, 3);
  T* du_buf = backward_scratch<T, kScratchRotMapU>(static_cast<std::size_t>(3 * n_rows));
  T* dt_buf = backward_scratch<T, kScratchRotMapT>(static_cast<std::size_t>(3 * n_rows));
  MatMap<T> du(du_buf, n_rows, 3), dt(dt_buf, n_rows, 3);
  const auto g = node.out.grd();
  du.noalias() = g * W.val();  // out = u W^T
  if (W.grad) W.grd().noalias() += g.transpose() * u;
  dt.setZero();
#pragma omp parallel for schedule(static) if (n_rows * 36 > kParallelMin)
  for (int64_t n = 0; n < n_rows; ++n)
    mat3_apply_backward(R.value + 9 * n, saved + 3 * n, du_buf + 3 * n, transpose, R.grad ? R.grad + 9 * n : nullptr,
                        dt_buf + 3 * n);
  if (v.grad) v.grd().noalias() += dt * W.val().transpose();  // t = v W
  if (W.grad) W.grd().noalias() += v.val().transpose() * dt;
}

#define LAYERSNET_INSTANTIATE(T)                                                                     \
  template Var<T> row_norm<T>(Tape<T>&, const Var<T>&);                                             \
  template Var<T> row_normalize<T>(Tape<T>&, const Var<T>&, T);                                     \
  template Var<T> cross3<T>(Tape<T>&, const Var<T>&, const Var<T>&);                                \
  template Var<T> rotate3<T>(Tape<T>&, const Var<T>&, const Var<T>&, bool);                         \
  template Var<T> rot_map_apply<T>(Tape<T>&, const Var<T>&, const Var<T>&, const Var<T>&, bool);    \
  template void backward_row_norm<T>(const Node<T>&);                                               \
  template void backward_row_normalize<T>(const Node<T>&);                                          \
  template void backward_cross3<T>(const Node<T>&);                                                 \
  template void backward_rotate3<T>(const Node<T>&);                                                \
  template void backward_rot_map_apply<T>(const Node<T>&);
LAYERSNET_INSTANTIATE(float)
LAYERSNET_INSTANTIATE(double)
#undef LAYERSNET_INSTANTIATE

}  // namespace layersnet::ad
