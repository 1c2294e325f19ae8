#include "autodiff/ops_solve.h"

#include "autodiff/conjugate_gradients.h"
#include "autodiff/ops_graph.h"

#include <Eigen/Dense>

#include <cmath>
#include <vector>

namespace layersnet::ad {
namespace {

template <class T>
void check_system(const BlockSpd<T>& A, int64_t rows, int64_t cols) {
  const int64_t N = static_cast<int64_t>(A.offsets.size()) - 1;
  LAYERSNET_CHECK(N >= 0 && rows == N && cols == 3,
                  "block_spd_solve: b is (" << rows << ", " << cols << ") but A has " << N << " block rows of 3");
  check_csr("block_spd_solve", A.offsets, static_cast<int64_t>(A.columns.size()));
  check_indices("block_spd_solve", A.columns, N);
  LAYERSNET_CHECK(A.blocks.size() == 9 * A.columns.size() && static_cast<int64_t>(A.scale.size()) == N,
                  "block_spd_solve: " << A.columns.size() << " blocks need " << 9 * A.columns.size() << " values (got "
                                      << A.blocks.size() << ") and " << N << " block rows a scale each (got "
                                      << A.scale.size() << ")");
  LAYERSNET_CHECK(A.iterations >= 1 && A.tolerance >= T(0),
                  "block_spd_solve: " << A.iterations << " iterations and tolerance " << A.tolerance
                                      << "; give at least one iteration and a tolerance >= 0");
}

// A⁻¹ (s ⊙ rhs), or A⁻¹ rhs without `scale_rhs`, by preconditioned conjugate gradients started
// at zero. rhs: (N, 3).
template <class T>
std::vector<double> solve(const BlockSpd<T>& A, const T* rhs, bool scale_rhs) {
  const int64_t N = static_cast<int64_t>(A.offsets.size()) - 1;
  using Block = Eigen::Matrix3d;
  std::vector<Block> inverse_diagonal(N, Block::Zero());
  for (int64_t r = 0; r < N; ++r)
    for (int32_t k = A.offsets[r]; k < A.offsets[r + 1]; ++k)
      if (A.columns[k] == r) {
        Block d;
        for (int e = 0; e < 9; ++e) d(e / 3, e % 3) = static_cast<double>(A.blocks[9 * k + e]);
        if (std::fabs(d.determinant()) > 1e-300) inverse_diagonal[r] = d.inverse();
      }
  std::vector<double> rhs_scaled(static_cast<std::size_t>(3 * N));
  for (int64_t r = 0; r < N; ++r)
    for (int c = 0; c < 3; ++c)
      rhs_scaled[3 * r + c] = (scale_rhs ? static_cast<double>(A.scale[r]) : 1.0) * static_cast<double>(rhs[3 * r + c]);
  auto multiply = [&](const std::vector<double>& p, std::vector<double>& y, int64_t r0, int64_t r1) {
    for (int64_t r = r0; r < r1; ++r) {
      Eigen::Vector3d acc = Eigen::Vector3d::Zero();
      for (int32_t k = A.offsets[r]; k < A.offsets[r + 1]; ++k) {
        const T* b = &A.blocks[9 * k];
        const double* pc = &p[3 * A.columns[k]];
        for (int i = 0; i < 3; ++i)
          acc[i] += static_cast<double>(b[3 * i]) * pc[0] + static_cast<double>(b[3 * i + 1]) * pc[1] +
                    static_cast<double>(b[3 * i + 2]) * pc[2];
      }
      for (int i = 0; i < 3; ++i) y[3 * r + i] = acc[i];
    }
  };
  auto precondition = [&](const std::vector<double>& from, std::vector<double>& to, int64_t r0, int64_t r1) {
    for (int64_t r = r0; r < r1; ++r) {
      const Eigen::Vector3d y = inverse_diagonal[r] * Eigen::Vector3d(from[3 * r], from[3 * r + 1], from[3 * r + 2]);
      for (int c = 0; c < 3; ++c) to[3 * r + c] = y[c];
    }
  };
  const double tolerance = static_cast<double>(A.tolerance);
  return conjugate_gradients(std::move(rhs_scaled), multiply, precondition, A.iterations, tolerance * tolerance);
}

}  // namespace

// Node: in[0] = b; BlockSpd (views into the arena).
template <class T>
Var<T> block_spd_solve(Tape<T>& tape, const BlockSpd<T>& A, const Var<T>& b) {
  check_system(A, b.rows, b.cols);
  const bool grad = tape.wants_grad({b});
  Var<T> out = tape.new_var(b.rows, 3, grad);
  const std::vector<double> x = solve(A, b.value, true);
  for (std::size_t k = 0; k < x.size(); ++k) out.value[k] = static_cast<T>(x[k]);
  if (grad) {
    BlockSpd<T> kept = A;
    kept.offsets = tape.copy_to_arena(A.offsets);
    kept.columns = tape.copy_to_arena(A.columns);
    kept.blocks = tape.copy_to_arena(A.blocks);
    kept.scale = tape.copy_to_arena(A.scale);
    tape.record(OpKind::BlockSpdSolve, out, {b}, kept);
  }
  return out;
}

template <class T>
void backward_block_spd_solve(const Node<T>& node) {
  const Var<T>& b = node.in[0];
  if (!b.grad) return;
  const BlockSpd<T>& A = std::get<BlockSpd<T>>(node.params);
  const std::vector<double> y = solve(A, node.out.grad, false);  // A⁻¹ dout, then s ⊙ it
  for (int64_t r = 0; r < b.rows; ++r)
    for (int c = 0; c < 3; ++c) b.grad[3 * r + c] += static_cast<T>(static_cast<double>(A.scale[r]) * y[3 * r + c]);
}

#define LAYERSNET_INSTANTIATE(T)                                                     \
  template Var<T> block_spd_solve<T>(Tape<T>&, const BlockSpd<T>&, const Var<T>&); \
  template void backward_block_spd_solve<T>(const Node<T>&);
LAYERSNET_INSTANTIATE(float)
LAYERSNET_INSTANTIATE(double)
#undef LAYERSNET_INSTANTIATE

}  // namespace layersnet::ad
