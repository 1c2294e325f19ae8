#include "autodiff/ops_dense.h"

#include "autodiff/bf16_gemm.h"
#include "autodiff/gemm_f32.h"
#include "autodiff/row_blocks.h"

#include <algorithm>
#include <cmath>

namespace layersnet::ad {

namespace {

template <class T>
using RowVecMap = Eigen::Map<Eigen::Matrix<T, 1, Eigen::Dynamic>>;
template <class T>
using ConstRowVecMap = Eigen::Map<const Eigen::Matrix<T, 1, Eigen::Dynamic>>;

template <class T>
bool absent(const Var<T>& v) {
  return v.value == nullptr;
}

// dst[i] += src[i] for n values, over the threads in blocks.
template <class T>
void add_in_place(T* dst, const T* src, int64_t n) {
  for_row_blocks(n / 256 + 1, 256, [&](int64_t b0, int64_t nb) {
    const int64_t i0 = b0 * 256, i1 = std::min(n, (b0 + nb) * 256);
    for (int64_t i = i0; i < i1; ++i) dst[i] += src[i];
  });
}

// b broadcast to a's (N, C): b is (N, C), (1, C), (N, 1) or (1, 1).
template <class T>
void check_broadcast(const char* op, const Var<T>& a, const Var<T>& b) {
  LAYERSNET_CHECK((b.rows == a.rows || b.rows == 1) && (b.cols == a.cols || b.cols == 1),
                  op << ": cannot broadcast (" << b.rows << ", " << b.cols << ") to (" << a.rows << ", "
                     << a.cols << "); b must be (N, C), (1, C), (N, 1) or (1, 1)");
}

template <class T>
void check_same_shape(const char* op, const Var<T>& a, const Var<T>& b) {
  LAYERSNET_CHECK(a.rows == b.rows && a.cols == b.cols,
                  op << ": shapes (" << a.rows << ", " << a.cols << ") and (" << b.rows << ", " << b.cols
                     << ") differ");
}

// Calls f with rows [r0, r0 + n) of b broadcast to (n, cols), as an Eigen matrix expression.
// A broadcast row or column is first written out into a per-thread block (one row block, in
// L2): Eigen's replicate() expressions index every element and do not vectorise, which made
// the broadcast products several times slower than the same-shape ones.
template <class T, class F>
void with_b_block(const Var<T>& b, int64_t rows, int64_t cols, int64_t r0, int64_t n, F&& f) {
  const ConstMatMap<T> bv(b.value, b.rows, b.cols);
  if (b.rows == rows && b.cols == cols) {
    f(bv.middleRows(r0, n));
  } else if (b.rows == 1 && b.cols == 1) {
    f(RowMat<T>::Constant(n, cols, b.value[0]));
  } else {
    static thread_local std::vector<T> buffer;  // grows to one row block, then reused
    if (buffer.size() < static_cast<std::size_t>(n * cols)) buffer.resize(static_cast<std::size_t>(n * cols));
    MatMap<T> dense(buffer.data(), n, cols);
    if (b.rows == 1) {
      for (int64_t r = 0; r < n; ++r) dense.row(r) = bv.row(0);
    } else {
      for (int64_t r = 0; r < n; ++r) dense.row(r).setConstant(b.value[r0 + r]);
    }
    f(ConstMatMap<T>(buffer.data(), n, cols));
  }
}

// Adds the (rows, cols) gradient e(r0, n, bb), reduced onto b's broadcast shape, into b's
// gradient. e returns an Eigen matrix expression for rows [r0, r0 + n); bb is b broadcast
// to those rows (for ops whose gradient depends on b).
template <class T, class E>
void accumulate_broadcast(const Var<T>& b, int64_t rows, int64_t cols, E&& e) {
  MatMap<T> gb(b.grad, b.rows, b.cols);
  const ConstMatMap<T> bv(b.value, b.rows, b.cols);
  if (b.rows == rows && b.cols == cols) {
    for_row_blocks(rows, cols,
                   [&](int64_t r0, int64_t n) { gb.middleRows(r0, n) += e(r0, n, bv.middleRows(r0, n)); });
  } else if (b.cols == 1 && b.rows == rows) {
    for_row_blocks(rows, cols, [&](int64_t r0, int64_t n) {
      gb.middleRows(r0, n) += e(r0, n, bv.middleRows(r0, n).replicate(1, cols)).rowwise().sum();
    });
  } else if (b.rows == 1 && b.cols == cols) {
    const T* s = reduce_row_blocks<T>(rows, cols, cols, [&](int64_t r0, int64_t n, T* p) {
      RowVecMap<T>(p, cols) += e(r0, n, bv.replicate(n, 1)).colwise().sum();
    });
    for (int64_t c = 0; c < cols; ++c) b.grad[c] += s[c];
  } else {
    const T* s = reduce_row_blocks<T>(rows, cols, 1, [&](int64_t r0, int64_t n, T* p) {
      *p += e(r0, n, RowMat<T>::Constant(n, cols, b.value[0])).sum();
    });
    b.grad[0] += s[0];
  }
}

// out = f(a, b broadcast) elementwise; f takes and returns Eigen array expressions.
template <class T, class F>
Var<T> binary_op(Tape<T>& tape, OpKind kind, const char* name, const Var<T>& a, const Var<T>& b, F&& f) {
  check_broadcast(name, a, b);
  const bool grad = tape.wants_grad({a, b});
  Var<T> out = tape.new_var(a.rows, a.cols, grad);
  const ConstMatMap<T> av(a.value, a.rows, a.cols);
  MatMap<T> ov(out.value, out.rows, out.cols);
  for_row_blocks(a.rows, a.cols, [&](int64_t r0, int64_t n) {
    with_b_block(b, a.rows, a.cols, r0, n, [&](const auto& bb) {
      ov.middleRows(r0, n).array() = f(av.middleRows(r0, n).array(), bb.array());
    });
  });
  if (grad) tape.record(kind, out, {a, b});
  return out;
}

// out = f(x) elementwise.
template <class T, class F>
void unary_forward(const Var<T>& x, Var<T>& out, F&& f) {
  const ConstMatMap<T> xv(x.value, x.rows, x.cols);
  MatMap<T> ov(out.value, out.rows, out.cols);
  for_row_blocks(x.rows, x.cols,
                 [&](int64_t r0, int64_t n) { ov.middleRows(r0, n).array() = f(xv.middleRows(r0, n).array()); });
}

// dx += f(x, dout) elementwise.
template <class T, class F>
void unary_backward(const Var<T>& x, const Var<T>& out, F&& f) {
  if (!x.grad) return;
  const ConstMatMap<T> xv(x.value, x.rows, x.cols), g(out.grad, out.rows, out.cols);
  MatMap<T> gx(x.grad, x.rows, x.cols);
  for_row_blocks(x.rows, x.cols, [&](int64_t r0, int64_t n) {
    gx.middleRows(r0, n).array() += f(xv.middleRows(r0, n).array(), g.middleRows(r0, n).array());
  });
}

}  // namespace

// ---- linear -----------------------------------------------------------------------------
// Threads: our loop owns them, Eigen runs single-threaded inside each chunk of rows.
// Eigen's own threaded GEMM synchronises its threads by spinning once per panel of the
// inner dimension; for dW = dyᵀ x (inner dimension N = 80,000) that is hundreds of spins,
// ruinous on a shared machine. Independent row chunks need one join per call.
//
// Rows are cut into a number of chunks that depends only on N, so dW and db (sums over
// the chunks, added in chunk order) are bit-identical for any thread count.

namespace {

// 16 chunks for large N (balances 1, 2, 4, 8 threads); chunks of >= 256 rows otherwise. Eigen's
// product rounds a row by where it falls in the call, so the chunks fix the float32 results
// (training's and float32 rollouts'). Under bf16 products, an inference-only mode, chunks of >= 64
// rows split a frame's few hundred patch tokens over the threads with one fork per op, not one
// per layer and row block inside it (docs/decisions.md, "Rollouts' threads spin a moment before
// they sleep").
int64_t linear_chunks(int64_t n, bool fine) { return std::clamp<int64_t>(n / (fine ? 64 : 256), 1, 16); }

template <class F>
void for_linear_chunks(int64_t n, int64_t width, bool fine, F&& f) {
  const int64_t chunks = linear_chunks(n, fine);
#pragma omp parallel for schedule(dynamic, 1) if (chunks > 1 && run_parallel(n, width))
  for (int64_t k = 0; k < chunks; ++k) {
    const int64_t r0 = n * k / chunks, r1 = n * (k + 1) / chunks;
    f(k, r0, r1 - r0);
  }
}

}  // namespace

// Rows of a block small enough to stay in the L2 cache from the fill through the GEMM to the
// ReLU, for outputs `width` wide (a narrow x makes the output's passes the main cost).
int64_t cache_block_rows(int64_t width) { return std::max<int64_t>(64, (int64_t{64} << 10) / std::max<int64_t>(1, width)); }

// Whether this tape type's products run on the float32 kernel of autodiff/gemm_f32.h (float
// tapes where it is chosen); Eigen's product otherwise.
template <class T>
bool own_gemm() {
  if constexpr (std::is_same_v<T, float>) return f32_gemm_kernel() != F32GemmKernel::kEigen;
  return false;
}

// Wᵀ (Cin, Cout) row-major, which the own kernel reads as B of x Wᵀ; empty where Eigen runs.
template <class T>
std::vector<T> transposed_for_gemm(const ConstMatMap<T>& W) {
  if (!own_gemm<T>()) return {};
  std::vector<T> t(static_cast<std::size_t>(W.size()));
  MatMap<T>(t.data(), W.cols(), W.rows()) = W.transpose();
  return t;
}

// out = residual + x Wᵀ + b (then max(., 0) with relu) for one block of n rows, serially: one
// GEMM accumulating into rows pre-filled with the residual and the bias (Eigen's `=` product
// would zero-fill first anyway, so both cost no extra pass). x: (n, Cin); W: (Cout, Cin);
// Wt: W's transposed_for_gemm, empty for Eigen; b: (Cout) or null; residual: (n, Cout) or
// null; out: (n, Cout).
template <class T>
void dense_block(const T* x, int64_t n, const ConstMatMap<T>& W, const std::vector<T>& Wt, const T* b,
                 const T* residual, bool relu, T* out) {
  MatMap<T> rows(out, n, W.rows());
  if (residual) {
    const ConstMatMap<T> res(residual, n, W.rows());
    if (b) rows = res.rowwise() + ConstRowVecMap<T>(b, W.rows());
    else rows = res;
  } else if (b) {
    rows.rowwise() = ConstRowVecMap<T>(b, W.rows());
  } else {
    rows.setZero();
  }
  if constexpr (std::is_same_v<T, float>) {
    if (!Wt.empty())
      gemm_f32(f32_gemm_kernel(), n, W.rows(), W.cols(), x, W.cols(), 1, Wt.data(), W.rows(), out, W.rows(), false);
  }
  if (Wt.empty()) rows.noalias() += ConstMatMap<T>(x, n, W.cols()) * W.transpose();
  if (relu) rows = rows.cwiseMax(T(0));
}

// out = residual + x Wᵀ + b (then ReLU), chunk by chunk over the threads and block by block
// within a chunk. x: (N, Cin); W: (Cout, Cin); b: (Cout) or null; residual: (N, Cout) or
// null; out: (N, Cout).
template <class T>
void linear_forward(const ConstMatMap<T>& x, const ConstMatMap<T>& W, const T* b, bool relu, MatMap<T> out,
                    bool fine_chunks, const T* residual = nullptr) {
  const int64_t block = cache_block_rows(out.cols()), cin = x.cols(), cout = out.cols();
  const std::vector<T> Wt = transposed_for_gemm(W);
  for_linear_chunks(x.rows(), cin + cout, fine_chunks, [&](int64_t, int64_t c0, int64_t c_rows) {
    for (int64_t r0 = c0; r0 < c0 + c_rows; r0 += block)
      dense_block(x.data() + r0 * cin, std::min(block, c0 + c_rows - r0), W, Wt, b,
                  residual ? residual + r0 * cout : nullptr, relu, out.data() + r0 * cout);
  });
}

// dx += dy W (per chunk of rows); dW += Σ_chunks dy_kᵀ x_k; db += Σ_chunks colsum(dy_k).
// dy: (N, Cout); dx: (N, Cin) or null; dW: (Cout, Cin) or null; db: (Cout) or null.
// With y (the relu output) and dz (N, Cout scratch) given, dy is first masked per chunk:
// dz = dy * (y > 0), then used in place of dy.
// With assign_dx, dx = dy W instead (dx need not be initialised).
template <class T>
void linear_backward(const ConstMatMap<T>& x, const ConstMatMap<T>& W, const ConstMatMap<T>& dy, T* dx, T* dW,
                     T* db, const T* y = nullptr, T* dz = nullptr, bool assign_dx = false) {
  const int64_t n = x.rows(), cin = x.cols(), cout = W.rows(), chunks = linear_chunks(n, false);
  // Per-chunk partials [dW_k (cout*cin) | db_k (cout)]; grows once, then reused.
  static thread_local std::vector<T> partial;
  const int64_t stride = cout * cin + cout;
  if (chunks > 1 && (dW || db)) partial.resize(static_cast<std::size_t>(chunks * stride));
  T* const base = partial.data();  // captured: inside the workers `partial` names THEIR buffer
  const bool own = own_gemm<T>();
  const F32GemmKernel kernel = f32_gemm_kernel();
  for_linear_chunks(n, cin + cout, false, [&](int64_t k, int64_t r0, int64_t rows) {
    if (y) {
      MatMap<T> dz_k(dz + r0 * cout, rows, cout);
      dz_k = (ConstMatMap<T>(y + r0 * cout, rows, cout).array() > T(0)).select(dy.middleRows(r0, rows), T(0));
    }
    const ConstMatMap<T> dy_k((y ? dz : dy.data()) + r0 * cout, rows, cout);
    T* const dW_k = chunks == 1 ? dW : base + k * stride;  // no partials: straight into the gradients
    if constexpr (std::is_same_v<T, float>) {
      if (own) {
        if (dx) gemm_f32(kernel, rows, cin, cout, dy_k.data(), cout, 1, W.data(), cin, dx + r0 * cin, cin, assign_dx);
        if (dW)
          gemm_f32(kernel, cout, cin, rows, dy_k.data(), 1, cout, x.data() + r0 * cin, cin, dW_k, cin, chunks > 1);
      }
    }
    if (!own) {
      if (dx && assign_dx) MatMap<T>(dx + r0 * cin, rows, cin).noalias() = dy_k * W;
      else if (dx) MatMap<T>(dx + r0 * cin, rows, cin).noalias() += dy_k * W;
      if (dW && chunks == 1) MatMap<T>(dW, cout, cin).noalias() += dy_k.transpose() * x.middleRows(r0, rows);
      else if (dW) MatMap<T>(dW_k, cout, cin).noalias() = dy_k.transpose() * x.middleRows(r0, rows);
    }
    if (chunks == 1) {
      if (db) RowVecMap<T>(db, cout) += dy_k.colwise().sum();
      return;
    }
    if (db) RowVecMap<T>(base + k * stride + cout * cin, cout) = dy_k.colwise().sum();
  });
  if (chunks == 1 || !(dW || db)) return;
  // Add the partials in chunk order, in parallel over the entries of [dW | db] that are wanted,
  // 64 at a time (so that the adds vectorise; each entry's sum keeps the chunk order).
  const int64_t lo = dW ? 0 : cout * cin, hi = db ? stride : cout * cin;
  for_row_blocks((hi - lo + 63) / 64, 64, [&](int64_t b0, int64_t nb) {
    for (int64_t j0 = lo + b0 * 64; j0 < std::min(hi, lo + (b0 + nb) * 64); j0 += 64) {
      const int64_t width = std::min<int64_t>(64, hi - j0);
      T acc[64] = {};
      for (int64_t k = 0; k < chunks; ++k) {
        const T* part = base + k * stride + j0;
        for (int64_t j = 0; j < width; ++j) acc[j] += part[j];
      }
      for (int64_t j = 0; j < width; ++j) (j0 + j < cout * cin ? dW[j0 + j] : db[j0 + j - cout * cin]) += acc[j];
    }
  });
}

namespace {

// The bf16 weights a product by W runs on: packed when the tape's matmul precision is bf16
// and W is at least kBf16MinChannels wide both ways (narrower products, the model's transposes
// by an identity and its 3-D maps, stay float: bf16 would make them lossy and gains nothing);
// null otherwise. bf16 on a recording tape or a double tape throws, naming `op`.
template <class T>
std::shared_ptr<const Bf16PackedWeights> bf16_weights_of(const Tape<T>& tape, const Var<T>& W, const char* op) {
  if (tape.matmul_precision() != MatmulPrecision::kBFloat16) return nullptr;
  LAYERSNET_CHECK(!tape.recording(), op << ": matmul precision bf16 is for inference only, but the tape is recording; "
                                           "run the forward under ad::NoRecord, or set_matmul_precision(kFloat32) to train");
  LAYERSNET_CHECK((std::is_same_v<T, float>), op << ": matmul precision bf16 needs a float tape (this one is double)");
  if constexpr (std::is_same_v<T, float>) {
    if (W.cols >= kBf16MinChannels && W.rows >= kBf16MinChannels) return bf16_cached_weights(W.value, W.rows, W.cols);
  }
  return nullptr;
}

template <class T>
Var<T> linear_op(Tape<T>& tape, const Var<T>& x, const Var<T>& W, const Var<T>& b, bool relu,
                 const Var<T>& residual = {}) {
  LAYERSNET_CHECK(x.cols == W.cols, "linear: x is (" << x.rows << ", " << x.cols << ") but W is (" << W.rows << ", "
                                                     << W.cols << "); W must be (Cout, Cin) in torch layout");
  LAYERSNET_CHECK(absent(b) || (b.rows == 1 && b.cols == W.rows),
                  "linear: bias is (" << b.rows << ", " << b.cols << "), expected (1, " << W.rows << ") or empty");
  LAYERSNET_CHECK(absent(residual) || (residual.rows == x.rows && residual.cols == W.rows),
                  "linear_add: the residual is (" << residual.rows << ", " << residual.cols << "), expected ("
                                                  << x.rows << ", " << W.rows << ")");
  const auto packed = bf16_weights_of(tape, W, "linear");
  if constexpr (std::is_same_v<T, float>) {
    if (packed) {
      Var<T> out = tape.new_var(x.rows, W.rows, false);
      bf16_linear_forward(x.value, x.rows, x.cols, *packed, b.value, relu, out.value);
      if (residual.value) add_in_place(out.value, residual.value, out.size());
      return out;
    }
  }
  const bool grad = tape.wants_grad({x, W, b, residual});
  Var<T> out = tape.new_var(x.rows, W.rows, grad);
  linear_forward<T>({x.value, x.rows, x.cols}, {W.value, W.rows, W.cols}, b.value, relu, out.val(),
                    tape.matmul_precision() == MatmulPrecision::kBFloat16, residual.value);
  if (grad) tape.record(relu ? OpKind::LinearRelu : OpKind::Linear, out, {x, W, b, residual});
  return out;
}

}  // namespace

template <class T>
Var<T> linear(Tape<T>& tape, const Var<T>& x, const Var<T>& W, const Var<T>& b) {
  return linear_op(tape, x, W, b, false);
}

template <class T>
Var<T> linear_add(Tape<T>& tape, const Var<T>& x, const Var<T>& W, const Var<T>& b, const Var<T>& residual) {
  LAYERSNET_CHECK(!absent(residual), "linear_add: the residual is empty; use linear");
  return linear_op(tape, x, W, b, false, residual);
}

template <class T>
void backward_linear(const Node<T>& node) {
  const auto& [x, W, b, residual] = node.in;
  linear_backward<T>({x.value, x.rows, x.cols}, {W.value, W.rows, W.cols},
                     {node.out.grad, node.out.rows, node.out.cols}, x.grad, W.grad, b.grad);
  if (residual.grad) add_in_place(residual.grad, node.out.grad, node.out.size());
}

template <class T>
Var<T> linear_relu(Tape<T>& tape, const Var<T>& x, const Var<T>& W, const Var<T>& b) {
  return linear_op(tape, x, W, b, true);
}

template <class T>
void backward_linear_relu(const Node<T>& node) {
  const auto& [x, W, b, unused] = node.in;
  linear_backward<T>({x.value, x.rows, x.cols}, {W.value, W.rows, W.cols},
                     {node.out.grad, node.out.rows, node.out.cols}, x.grad, W.grad, b.grad, node.out.value,
                     backward_scratch<T, kScratchLinearRelu>(static_cast<std::size_t>(node.out.size())));
}

// ---- mlp --------------------------------------------------------------------------------
// Node: in[0] = x; MlpParams; saved = [h_1 (N, C_1) | ... | h_{k-1}] when recording.

namespace {

// Two hidden blocks of one thread (the layer's input and output), grown once, then reused.
template <class T>
T* mlp_block_scratch(std::size_t count) {
  static thread_local std::vector<T> buffer;
  if (buffer.size() < count) buffer.resize(count);
  return buffer.data();
}

}  // namespace

template <class T>
Var<T> mlp(Tape<T>& tape, const Var<T>& x, std::span<const Var<T>> weights, std::span<const Var<T>> biases,
           bool final_relu) {
  const auto L = static_cast<int64_t>(weights.size());
  LAYERSNET_CHECK(L >= 1 && biases.size() == weights.size(),
                  "mlp: " << weights.size() << " weights and " << biases.size() << " biases; need one of each per layer");
  bool grad = x.grad != nullptr;
  int64_t cin = x.cols, hidden_total = 0, widest = 0, width_sum = x.cols;
  for (int64_t i = 0; i < L; ++i) {
    const Var<T>& W = weights[i];
    const Var<T>& b = biases[i];
    LAYERSNET_CHECK(W.cols == cin, "mlp: layer " << i << "'s weight is (" << W.rows << ", " << W.cols << ") but its input has "
                                                 << cin << " columns; W must be (Cout, Cin) in torch layout");
    LAYERSNET_CHECK(absent(b) || (b.rows == 1 && b.cols == W.rows),
                    "mlp: layer " << i << "'s bias is (" << b.rows << ", " << b.cols << "), expected (1, " << W.rows
                                  << ") or empty");
    grad |= W.grad != nullptr || b.grad != nullptr;
    if (i + 1 < L) hidden_total += W.rows;
    widest = std::max(widest, W.rows);
    width_sum += W.rows;
    cin = W.rows;
  }
  grad = tape.recording() ? grad : tape.profiling();
  const bool save = grad && tape.recording();
  const int64_t N = x.rows;
  Var<T> out = tape.new_var(N, cin, grad);
  T* saved = save ? tape.scratch(static_cast<std::size_t>(N * hidden_total)) : nullptr;

  // Per layer: bf16 packed weights where the matmul precision asks for them (as linear).
  std::vector<std::shared_ptr<const Bf16PackedWeights>> packed(static_cast<std::size_t>(L));
  for (int64_t i = 0; i < L; ++i) packed[i] = bf16_weights_of(tape, weights[i], "mlp");
  std::vector<std::vector<T>> transposed(static_cast<std::size_t>(L));
  for (int64_t i = 0; i < L; ++i)
    if (!packed[i]) transposed[i] = transposed_for_gemm<T>({weights[i].value, weights[i].rows, weights[i].cols});

  const int64_t block = cache_block_rows(widest);
  const bool fine_chunks = tape.matmul_precision() == MatmulPrecision::kBFloat16;
  for_linear_chunks(N, width_sum, fine_chunks, [&](int64_t, int64_t c0, int64_t c_rows) {
    T* ping = save ? nullptr : mlp_block_scratch<T>(static_cast<std::size_t>(2 * block * widest));
    for (int64_t r0 = c0; r0 < c0 + c_rows; r0 += block) {
      const int64_t n = std::min(block, c0 + c_rows - r0);
      const T* a = x.value + r0 * x.cols;
      int64_t offset = 0;  // of layer i's output in saved
      for (int64_t i = 0; i < L; ++i) {
        const Var<T>& W = weights[i];
        const bool relu = i + 1 < L || final_relu;
        T* dst = i + 1 == L ? out.value + r0 * W.rows
                 : save     ? saved + offset + r0 * W.rows
                            : ping + (i % 2) * block * widest;
        if constexpr (std::is_same_v<T, float>) {
          if (packed[i]) {
            bf16_linear_forward(a, n, W.cols, *packed[i], biases[i].value, relu, dst);
            a = dst, offset += N * W.rows;
            continue;
          }
        }
        dense_block<T>(a, n, {W.value, W.rows, W.cols}, transposed[i], biases[i].value, nullptr, relu, dst);
        a = dst, offset += N * W.rows;
      }
    }
  });
  if (grad) {
    const std::span<const Var<T>> w = tape.copy_to_arena(weights), b = tape.copy_to_arena(biases);
    tape.record(OpKind::Mlp, out, {x}, MlpParams<T>{w, b, final_relu}).saved = saved;
  }
  return out;
}

template <class T>
void backward_mlp(const Node<T>& node) {
  const Var<T>& x = node.in[0];
  const auto& prm = std::get<MlpParams<T>>(node.params);
  const auto L = static_cast<int64_t>(prm.weights.size());
  const int64_t N = x.rows;
  std::vector<int64_t> offset(static_cast<std::size_t>(L), 0);  // of h_{i+1} in saved
  for (int64_t i = 1; i < L; ++i) offset[i] = offset[i - 1] + N * prm.weights[i - 1].rows;
  const T* g = node.out.grad;  // gradient of layer i's output
  for (int64_t i = L - 1; i >= 0; --i) {
    const Var<T>& W = prm.weights[i];
    const Var<T>& b = prm.biases[i];
    const bool relu = i + 1 < L || prm.final_relu;
    const T* input = i == 0 ? x.value : node.saved + offset[i - 1];
    const T* y = !relu ? nullptr : i + 1 == L ? node.out.value : node.saved + offset[i];
    T* dz = relu ? backward_scratch<T, kScratchLinearRelu>(static_cast<std::size_t>(N * W.rows)) : nullptr;
    const auto in_size = static_cast<std::size_t>(N * W.cols);
    T* dx = i == 0 ? x.grad
            : i % 2 ? backward_scratch<T, kScratchMlpGradA>(in_size)
                    : backward_scratch<T, kScratchMlpGradB>(in_size);
    linear_backward<T>({input, N, W.cols}, {W.value, W.rows, W.cols}, {g, N, W.rows}, dx, W.grad, b.grad, y, dz,
                       /*assign_dx=*/i > 0);
    g = dx;
  }
}

// ---- add, sub, mul, div ---------------------------------------------------------------------

template <class T>
Var<T> add(Tape<T>& tape, const Var<T>& a, const Var<T>& b) {
  return binary_op(tape, OpKind::Add, "add", a, b, [](const auto& x, const auto& y) { return x + y; });
}

template <class T>
void backward_add(const Node<T>& node) {
  const auto& [a, b, u2, u3] = node.in;
  const ConstMatMap<T> g(node.out.grad, node.out.rows, node.out.cols);
  if (a.grad) accumulate_broadcast(a, a.rows, a.cols, [&](int64_t r0, int64_t n, const auto&) { return g.middleRows(r0, n); });
  if (b.grad) accumulate_broadcast(b, a.rows, a.cols, [&](int64_t r0, int64_t n, const auto&) { return g.middleRows(r0, n); });
}

template <class T>
Var<T> sub(Tape<T>& tape, const Var<T>& a, const Var<T>& b) {
  return binary_op(tape, OpKind::Sub, "sub", a, b, [](const auto& x, const auto& y) { return x - y; });
}

template <class T>
void backward_sub(const Node<T>& node) {
  const auto& [a, b, u2, u3] = node.in;
  const ConstMatMap<T> g(node.out.grad, node.out.rows, node.out.cols);
  if (a.grad) accumulate_broadcast(a, a.rows, a.cols, [&](int64_t r0, int64_t n, const auto&) { return g.middleRows(r0, n); });
  if (b.grad) accumulate_broadcast(b, a.rows, a.cols, [&](int64_t r0, int64_t n, const auto&) { return -g.middleRows(r0, n); });
}

template <class T>
Var<T> mul(Tape<T>& tape, const Var<T>& a, const Var<T>& b) {
  return binary_op(tape, OpKind::Mul, "mul", a, b, [](const auto& x, const auto& y) { return x * y; });
}

template <class T>
void backward_mul(const Node<T>& node) {
  const auto& [a, b, u2, u3] = node.in;
  const ConstMatMap<T> g(node.out.grad, a.rows, a.cols), av(a.value, a.rows, a.cols);
  if (a.grad) {
    MatMap<T> ga(a.grad, a.rows, a.cols);
    for_row_blocks(a.rows, a.cols, [&](int64_t r0, int64_t n) {
      with_b_block(b, a.rows, a.cols, r0, n, [&](const auto& bb) {
        ga.middleRows(r0, n).array() += g.middleRows(r0, n).array() * bb.array();
      });
    });
  }
  if (b.grad)
    accumulate_broadcast(b, a.rows, a.cols, [&](int64_t r0, int64_t n, const auto&) {
      return (g.middleRows(r0, n).array() * av.middleRows(r0, n).array()).matrix();
    });
}

template <class T>
Var<T> div(Tape<T>& tape, const Var<T>& a, const Var<T>& b) {
  return binary_op(tape, OpKind::Div, "div", a, b, [](const auto& x, const auto& y) { return x / y; });
}

// d(a/b)/da = 1/b; d(a/b)/db = -(a/b)/b = -out/b.
template <class T>
void backward_div(const Node<T>& node) {
  const auto& [a, b, u2, u3] = node.in;
  const ConstMatMap<T> g(node.out.grad, a.rows, a.cols), ov(node.out.value, a.rows, a.cols);
  if (a.grad) {
    MatMap<T> ga(a.grad, a.rows, a.cols);
    for_row_blocks(a.rows, a.cols, [&](int64_t r0, int64_t n) {
      with_b_block(b, a.rows, a.cols, r0, n, [&](const auto& bb) {
        ga.middleRows(r0, n).array() += g.middleRows(r0, n).array() / bb.array();
      });
    });
  }
  if (b.grad)
    accumulate_broadcast(b, a.rows, a.cols, [&](int64_t r0, int64_t n, const auto& bb) {
      return (-(g.middleRows(r0, n).array() * ov.middleRows(r0, n).array()) / bb.array()).matrix();
    });
}

// ---- scale, relu, hinge_sq ------------------------------------------------------------------

template <class T>
Var<T> scale(Tape<T>& tape, const Var<T>& x, std::type_identity_t<T> c) {
  const bool grad = tape.wants_grad({x});
  Var<T> out = tape.new_var(x.rows, x.cols, grad);
  unary_forward(x, out, [c](const auto& v) { return v * c; });
  if (grad) tape.record(OpKind::Scale, out, {x}, ScaleParams<T>{c});
  return out;
}

template <class T>
void backward_scale(const Node<T>& node) {
  const T c = std::get<ScaleParams<T>>(node.params).factor;
  unary_backward(node.in[0], node.out, [c](const auto&, const auto& g) { return g * c; });
}

template <class T>
Var<T> relu(Tape<T>& tape, const Var<T>& x) {
  const bool grad = tape.wants_grad({x});
  Var<T> out = tape.new_var(x.rows, x.cols, grad);
  unary_forward(x, out, [](const auto& v) { return v.max(T(0)); });
  if (grad) tape.record(OpKind::Relu, out, {x});
  return out;
}

template <class T>
void backward_relu(const Node<T>& node) {
  unary_backward(node.in[0], node.out, [](const auto& v, const auto& g) { return (v > T(0)).select(g, T(0)); });
}

template <class T>
Var<T> hinge_sq(Tape<T>& tape, const Var<T>& x, std::type_identity_t<T> thr) {
  const bool grad = tape.wants_grad({x});
  Var<T> out = tape.new_var(x.rows, x.cols, grad);
  unary_forward(x, out, [thr](const auto& v) { return (v - thr).min(T(0)).square(); });
  if (grad) tape.record(OpKind::HingeSq, out, {x}, HingeSqParams<T>{thr});
  return out;
}

template <class T>
void backward_hinge_sq(const Node<T>& node) {
  const T thr = std::get<HingeSqParams<T>>(node.params).threshold;
  unary_backward(node.in[0], node.out,
                 [thr](const auto& v, const auto& g) { return T(2) * (v - thr).min(T(0)) * g; });
}

// ---- layer_norm -----------------------------------------------------------------------------

// A row's sums add its columns one by one in order, each term rounded before it is added (never
// fused into the add), so a row's bits are those of a plain loop over its columns. One row's chain
// waits on every add's latency; kNormRows rows side by side keep the adders busy: their terms are
// first written column-major into a (C, kNormRows) buffer, so that the sums are vector adds with
// one row in each lane (and no multiply for the compiler to fuse into them).
constexpr int64_t kNormRows = 8;

// sums[j] = Σ_c terms[c * kNormRows + j] over c = 0..C-1 in order, for every lane j.
template <class T>
void column_sums(const T* terms, int64_t C, T* sums) {
  T acc[kNormRows] = {};
  for (int64_t c = 0; c < C; ++c)
    for (int64_t j = 0; j < kNormRows; ++j) acc[j] += terms[c * kNormRows + j];
  std::copy_n(acc, kNormRows, sums);
}

// x, out: (N, C); gamma, beta: (C) or null; mean, rstd: (N) saved for backward.
template <class T>
void layer_norm_forward(const T* x, const T* gamma, const T* beta, T eps, int64_t N, int64_t C, T* out, T* mean,
                        T* rstd) {
  for_row_blocks(N, C, [&](int64_t r0, int64_t n) {
    T* const terms = backward_scratch<T, kScratchLayerNorm>(static_cast<std::size_t>(C * kNormRows));
    T sums[kNormRows];
    for (int64_t g = r0; g < r0 + n; g += kNormRows) {
      const int64_t rows = std::min(kNormRows, r0 + n - g);
      // The mean, then the variance around it (two passes: no cancellation for rows with a large mean).
      for (int64_t j = 0; j < rows; ++j)
        for (int64_t c = 0; c < C; ++c) terms[c * kNormRows + j] = x[(g + j) * C + c];
      column_sums(terms, C, sums);
      for (int64_t j = 0; j < rows; ++j) mean[g + j] = sums[j] / T(C);
      for (int64_t j = 0; j < rows; ++j)
        for (int64_t c = 0; c < C; ++c) {
          const T d = x[(g + j) * C + c] - mean[g + j];
          terms[c * kNormRows + j] = d * d;
        }
      column_sums(terms, C, sums);
      for (int64_t j = 0; j < rows; ++j) rstd[g + j] = T(1) / std::sqrt(sums[j] / T(C) + eps);
    }
    for (int64_t r = r0; r < r0 + n; ++r) {
      const T *xr = x + r * C, m = mean[r], rs = rstd[r];
      T* yr = out + r * C;
      for (int64_t c = 0; c < C; ++c) {
        const T xh = (xr[c] - m) * rs;
        yr[c] = (gamma ? xh * gamma[c] : xh) + (beta ? beta[c] : T(0));
      }
    }
  });
}

// dy: (N, C); dx: (N, C) or null; dgamma, dbeta: (C) or null. All accumulate.
//   dx = rstd * (dxh - mean(dxh) - xh * mean(dxh * xh)),  dxh = dy * gamma.
template <class T>
void layer_norm_backward(const T* x, const T* gamma, const T* mean, const T* rstd, const T* dy, int64_t N, int64_t C,
                         T* dx, T* dgamma, T* dbeta) {
  if (dx) {
    for_row_blocks(N, C, [&](int64_t r0, int64_t n) {
      T* const dxh_terms = backward_scratch<T, kScratchLayerNorm>(static_cast<std::size_t>(2 * C * kNormRows));
      T* const dxh_xh_terms = dxh_terms + C * kNormRows;
      T mean_dxh[kNormRows], mean_dxh_xh[kNormRows];
      for (int64_t g = r0; g < r0 + n; g += kNormRows) {
        const int64_t rows = std::min(kNormRows, r0 + n - g);
        for (int64_t j = 0; j < rows; ++j) {
          const T *xr = x + (g + j) * C, *gr = dy + (g + j) * C;
          const T m = mean[g + j], rs = rstd[g + j];
          for (int64_t c = 0; c < C; ++c) {
            const T dxh = gamma ? gr[c] * gamma[c] : gr[c];
            dxh_terms[c * kNormRows + j] = dxh;
            dxh_xh_terms[c * kNormRows + j] = dxh * (xr[c] - m) * rs;
          }
        }
        column_sums(dxh_terms, C, mean_dxh);
        column_sums(dxh_xh_terms, C, mean_dxh_xh);
        for (int64_t j = 0; j < rows; ++j) {
          const int64_t r = g + j;
          const T *xr = x + r * C, *gr = dy + r * C;
          const T m = mean[r], rs = rstd[r], s1 = mean_dxh[j] / T(C), s2 = mean_dxh_xh[j] / T(C);
          T* dr = dx + r * C;
          for (int64_t c = 0; c < C; ++c) {
            const T dxh = gamma ? gr[c] * gamma[c] : gr[c];
            dr[c] += rs * (dxh - s1 - (xr[c] - m) * rs * s2);
          }
        }
      }
    });
  }
  if (dgamma || dbeta) {
    // Partial of width 2C per block: [Σ dy * xh | Σ dy].
    const T* s = reduce_row_blocks<T>(N, C, 2 * C, [&](int64_t r0, int64_t n, T* p) {
      for (int64_t r = r0; r < r0 + n; ++r) {
        const T *xr = x + r * C, *gr = dy + r * C;
        const T m = mean[r], rs = rstd[r];
        for (int64_t c = 0; c < C; ++c) {
          p[c] += gr[c] * (xr[c] - m) * rs;
          p[C + c] += gr[c];
        }
      }
    });
    for (int64_t c = 0; c < C; ++c) {
      if (dgamma) dgamma[c] += s[c];
      if (dbeta) dbeta[c] += s[C + c];
    }
  }
}

template <class T>
Var<T> layer_norm(Tape<T>& tape, const Var<T>& x, const Var<T>& gamma, const Var<T>& beta,
                  std::type_identity_t<T> eps) {
  for (const Var<T>* p : {&gamma, &beta})
    LAYERSNET_CHECK(absent(*p) || (p->rows == 1 && p->cols == x.cols),
                    "layer_norm: gamma/beta is (" << p->rows << ", " << p->cols << "), expected (1, " << x.cols
                                                  << ") or empty");
  LAYERSNET_CHECK(eps > T(0), "layer_norm: eps must be > 0 (a constant row divides by sqrt(eps))");
  const bool grad = tape.wants_grad({x, gamma, beta});
  Var<T> out = tape.new_var(x.rows, x.cols, grad);
  T* saved = tape.scratch(static_cast<std::size_t>(2 * x.rows));  // [mean (N) | rstd (N)]
  layer_norm_forward(x.value, gamma.value, beta.value, eps, x.rows, x.cols, out.value, saved, saved + x.rows);
  if (grad) tape.record(OpKind::LayerNorm, out, {x, gamma, beta}).saved = saved;
  return out;
}

template <class T>
void backward_layer_norm(const Node<T>& node) {
  const auto& [x, gamma, beta, unused] = node.in;
  layer_norm_backward(x.value, gamma.value, node.saved, node.saved + x.rows, node.out.grad, x.rows, x.cols, x.grad,
                      gamma.grad, beta.grad);
}

// ---- concat_cols, slice_cols -------------------------------------------------------------

template <class T>
Var<T> concat_cols(Tape<T>& tape, std::span<const Var<T>> inputs) {
  LAYERSNET_CHECK(!inputs.empty(), "concat_cols: no inputs");
  const int64_t N = inputs[0].rows;
  int64_t C = 0;
  bool grad = false;
  for (const auto& v : inputs) {
    LAYERSNET_CHECK(v.rows == N, "concat_cols: inputs have " << N << " and " << v.rows << " rows; all need the same");
    C += v.cols;
    grad |= v.grad != nullptr;
  }
  grad = tape.recording() ? grad : tape.profiling();
  Var<T> out = tape.new_var(N, C, grad);
  for_row_blocks(N, C, [&](int64_t r0, int64_t n) {
    for (int64_t r = r0; r < r0 + n; ++r) {
      T* dst = out.value + r * C;
      for (const auto& v : inputs) dst = std::copy_n(v.value + r * v.cols, v.cols, dst);
    }
  });
  if (grad) tape.record(OpKind::ConcatCols, out, {}, ConcatColsParams<T>{tape.copy_to_arena(inputs)});
  return out;
}

template <class T>
void backward_concat_cols(const Node<T>& node) {
  const ConstMatMap<T> g(node.out.grad, node.out.rows, node.out.cols);
  int64_t c0 = 0;
  for (const Var<T>& v : std::get<ConcatColsParams<T>>(node.params).inputs) {
    if (v.grad) {
      MatMap<T> gv(v.grad, v.rows, v.cols);
      for_row_blocks(v.rows, v.cols,
                     [&](int64_t r0, int64_t n) { gv.middleRows(r0, n) += g.block(r0, c0, n, v.cols); });
    }
    c0 += v.cols;
  }
}

template <class T>
Var<T> slice_cols(Tape<T>& tape, const Var<T>& x, int64_t c0, int64_t c1) {
  LAYERSNET_CHECK(0 <= c0 && c0 <= c1 && c1 <= x.cols,
                  "slice_cols: [" << c0 << ", " << c1 << ") is not inside the " << x.cols << " columns");
  const bool grad = tape.wants_grad({x});
  Var<T> out = tape.new_var(x.rows, c1 - c0, grad);
  const ConstMatMap<T> xv(x.value, x.rows, x.cols);
  MatMap<T> ov(out.value, out.rows, out.cols);
  for_row_blocks(x.rows, out.cols, [&](int64_t r0, int64_t n) { ov.middleRows(r0, n) = xv.block(r0, c0, n, c1 - c0); });
  if (grad) tape.record(OpKind::SliceCols, out, {x}, SliceColsParams{c0});
  return out;
}

template <class T>
void backward_slice_cols(const Node<T>& node) {
  const Var<T>& x = node.in[0];
  if (!x.grad) return;
  const ConstMatMap<T> g(node.out.grad, node.out.rows, node.out.cols);
  MatMap<T> gx(x.grad, x.rows, x.cols);
  const int64_t c0 = std::get<SliceColsParams>(node.params).first_col;
  for_row_blocks(x.rows, g.cols(),
                 [&](int64_t r0, int64_t n) { gx.block(r0, c0, n, g.cols()) += g.middleRows(r0, n); });
}

// ---- reductions (ReduceParams::factor: 1 for sums, 1/count for means) ----------------------

namespace {

template <class T>
Var<T> reduce_op(Tape<T>& tape, OpKind kind, const Var<T>& x, int64_t rows, int64_t cols, T factor) {
  const bool grad = tape.wants_grad({x});
  Var<T> out = tape.new_var(rows, cols, grad);
  const ConstMatMap<T> xv(x.value, x.rows, x.cols);
  if (kind == OpKind::RowSum) {
    MatMap<T> ov(out.value, out.rows, out.cols);
    for_row_blocks(x.rows, x.cols,
                   [&](int64_t r0, int64_t n) { ov.middleRows(r0, n) = xv.middleRows(r0, n).rowwise().sum() * factor; });
  } else {
    const int64_t width = out.size();  // 1 (SumAll) or C (ColSum)
    const T* s = reduce_row_blocks<T>(x.rows, x.cols, width, [&](int64_t r0, int64_t n, T* p) {
      if (width == 1) *p += xv.middleRows(r0, n).sum();
      else RowVecMap<T>(p, width) += xv.middleRows(r0, n).colwise().sum();
    });
    for (int64_t c = 0; c < width; ++c) out.value[c] = s[c] * factor;
  }
  if (grad) tape.record(kind, out, {x}, ReduceParams<T>{factor});
  return out;
}

// dx += factor * dout, dout broadcast back to x's shape like a (1, 1), (1, C) or (N, 1) operand.
template <class T>
void reduce_backward(const Node<T>& node) {
  const Var<T>& x = node.in[0];
  if (!x.grad) return;
  const T factor = std::get<ReduceParams<T>>(node.params).factor;
  Var<T> g = node.out;
  g.value = node.out.grad;
  MatMap<T> gx(x.grad, x.rows, x.cols);
  for_row_blocks(x.rows, x.cols, [&](int64_t r0, int64_t n) {
    with_b_block(g, x.rows, x.cols, r0, n, [&](const auto& gb) { gx.middleRows(r0, n) += gb * factor; });
  });
}

}  // namespace

template <class T>
Var<T> sum_all(Tape<T>& tape, const Var<T>& x) {
  return reduce_op(tape, OpKind::SumAll, x, 1, 1, T(1));
}
template <class T>
Var<T> mean_all(Tape<T>& tape, const Var<T>& x) {
  return reduce_op(tape, OpKind::SumAll, x, 1, 1, T(1) / T(std::max<int64_t>(x.size(), 1)));
}
template <class T>
Var<T> col_sum(Tape<T>& tape, const Var<T>& x) {
  return reduce_op(tape, OpKind::ColSum, x, 1, x.cols, T(1));
}
template <class T>
Var<T> col_mean(Tape<T>& tape, const Var<T>& x) {
  return reduce_op(tape, OpKind::ColSum, x, 1, x.cols, T(1) / T(std::max<int64_t>(x.rows, 1)));
}
template <class T>
Var<T> row_sum(Tape<T>& tape, const Var<T>& x) {
  return reduce_op(tape, OpKind::RowSum, x, x.rows, 1, T(1));
}
template <class T>
Var<T> row_mean(Tape<T>& tape, const Var<T>& x) {
  return reduce_op(tape, OpKind::RowSum, x, x.rows, 1, T(1) / T(std::max<int64_t>(x.cols, 1)));
}

template <class T>
void backward_sum_all(const Node<T>& node) {
  reduce_backward(node);
}
template <class T>
void backward_col_sum(const Node<T>& node) {
  reduce_backward(node);
}
template <class T>
void backward_row_sum(const Node<T>& node) {
  reduce_backward(node);
}

// ---- squared_error --------------------------------------------------------------------------

template <class T>
Var<T> squared_error(Tape<T>& tape, const Var<T>& a, const Var<T>& b) {
  check_same_shape("squared_error", a, b);
  const bool grad = tape.wants_grad({a, b});
  Var<T> out = tape.new_var(a.rows, 1, grad);
  const ConstMatMap<T> av(a.value, a.rows, a.cols), bv(b.value, b.rows, b.cols);
  MatMap<T> ov(out.value, out.rows, 1);
  for_row_blocks(a.rows, a.cols, [&](int64_t r0, int64_t n) {
    ov.middleRows(r0, n) = (av.middleRows(r0, n) - bv.middleRows(r0, n)).rowwise().squaredNorm();
  });
  if (grad) tape.record(OpKind::SquaredError, out, {a, b});
  return out;
}

// d/da = 2 (a - b) dout_i; d/db = -d/da.
template <class T>
void backward_squared_error(const Node<T>& node) {
  const auto& [a, b, u2, u3] = node.in;
  for_row_blocks(a.rows, a.cols, [&](int64_t r0, int64_t n) {
    for (int64_t r = r0; r < r0 + n; ++r) {
      const T w = T(2) * node.out.grad[r];
      for (int64_t c = 0; c < a.cols; ++c) {
        const T d = w * (a.value[r * a.cols + c] - b.value[r * a.cols + c]);
        if (a.grad) a.grad[r * a.cols + c] += d;
        if (b.grad) b.grad[r * a.cols + c] -= d;
      }
    }
  });
}

// ---- instantiation ------------------------------------------------------------------------

#define LAYERSNET_INSTANTIATE(T)                                                                   \
  template Var<T> linear<T>(Tape<T>&, const Var<T>&, const Var<T>&, const Var<T>&);                \
  template Var<T> linear_relu<T>(Tape<T>&, const Var<T>&, const Var<T>&, const Var<T>&);           \
  template Var<T> linear_add<T>(Tape<T>&, const Var<T>&, const Var<T>&, const Var<T>&, const Var<T>&); \
  template Var<T> mlp<T>(Tape<T>&, const Var<T>&, std::span<const Var<T>>, std::span<const Var<T>>, bool);  \
  template Var<T> add<T>(Tape<T>&, const Var<T>&, const Var<T>&);                                  \
  template Var<T> sub<T>(Tape<T>&, const Var<T>&, const Var<T>&);                                  \
  template Var<T> mul<T>(Tape<T>&, const Var<T>&, const Var<T>&);                                  \
  template Var<T> div<T>(Tape<T>&, const Var<T>&, const Var<T>&);                                  \
  template Var<T> scale<T>(Tape<T>&, const Var<T>&, T);                                            \
  template Var<T> relu<T>(Tape<T>&, const Var<T>&);                                                \
  template Var<T> hinge_sq<T>(Tape<T>&, const Var<T>&, T);                                         \
  template Var<T> layer_norm<T>(Tape<T>&, const Var<T>&, const Var<T>&, const Var<T>&, T);         \
  template Var<T> concat_cols<T>(Tape<T>&, std::span<const Var<T>>);                               \
  template Var<T> slice_cols<T>(Tape<T>&, const Var<T>&, int64_t, int64_t);                        \
  template Var<T> sum_all<T>(Tape<T>&, const Var<T>&);                                             \
  template Var<T> mean_all<T>(Tape<T>&, const Var<T>&);                                            \
  template Var<T> col_sum<T>(Tape<T>&, const Var<T>&);                                             \
  template Var<T> col_mean<T>(Tape<T>&, const Var<T>&);                                            \
  template Var<T> row_sum<T>(Tape<T>&, const Var<T>&);                                             \
  template Var<T> row_mean<T>(Tape<T>&, const Var<T>&);                                            \
  template Var<T> squared_error<T>(Tape<T>&, const Var<T>&, const Var<T>&);
LAYERSNET_INSTANTIATE(float)
LAYERSNET_INSTANTIATE(double)
#undef LAYERSNET_INSTANTIATE

#define LAYERSNET_INSTANTIATE_BACKWARD(Enum, stem) \
  template void backward_##stem<float>(const Node<float>&); \
  template void backward_##stem<double>(const Node<double>&);
LAYERSNET_DENSE_OPS(LAYERSNET_INSTANTIATE_BACKWARD)
#undef LAYERSNET_INSTANTIATE_BACKWARD

}  // namespace layersnet::ad
