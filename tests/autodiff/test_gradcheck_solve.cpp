// The block linear solve (autodiff/ops_solve.h): its output solves the system, its gradient
// checks in double, a pinned row stays at zero, and the result does not depend on the threads.
#include "autodiff/ops_solve.h"
#include "gradcheck_registry.h"

#include <Eigen/Dense>
#include <omp.h>

#include <cstring>
#include <vector>

namespace layersnet::ad::testing {
namespace {

// A chain of N vertices joined by spring-like blocks: A = diag(m) ⊗ I + Σ_edges K_e on
// (i, i), (j, j) and −K_e on (i, j), (j, i), with K_e = k (d dᵀ) + 0.1 k I for a random unit d.
// Symmetric positive definite. Row `pinned` (if >= 0) is cut out: identity, scale 0.
struct ChainSystem {
  std::vector<int32_t> offsets, columns;
  std::vector<double> blocks, scale;
  BlockSpd<double> view(int iterations = 200, double tolerance = 1e-13) const {
    return {offsets, columns, blocks, scale, iterations, tolerance};
  }
  Eigen::MatrixXd dense() const {
    const int64_t N = static_cast<int64_t>(offsets.size()) - 1;
    Eigen::MatrixXd A = Eigen::MatrixXd::Zero(3 * N, 3 * N);
    for (int64_t r = 0; r < N; ++r)
      for (int32_t k = offsets[r]; k < offsets[r + 1]; ++k)
        for (int e = 0; e < 9; ++e) A(3 * r + e / 3, 3 * columns[k] + e % 3) = blocks[9 * k + e];
    return A;
  }
};

ChainSystem chain(int N, double k, int pinned, unsigned seed) {
  const RowMat<double> dirs = random_matrix(N, 3, seed), mass = random_matrix(N, 1, seed + 1, 0.5, 2.0);
  std::vector<Eigen::Matrix3d> diag(N), off(N);  // off[i]: the block between i and i + 1
  for (int i = 0; i < N; ++i) diag[i] = mass(i, 0) * Eigen::Matrix3d::Identity();
  for (int i = 0; i + 1 < N; ++i) {
    const Eigen::Vector3d d = Eigen::Vector3d(dirs(i, 0), dirs(i, 1), dirs(i, 2)).normalized();
    off[i] = k * (d * d.transpose() + 0.1 * Eigen::Matrix3d::Identity());
    if (i != pinned && i + 1 != pinned) diag[i] += off[i], diag[i + 1] += off[i];
  }
  ChainSystem s;
  s.offsets.push_back(0);
  auto add = [&](int col, const Eigen::Matrix3d& b) {
    s.columns.push_back(col);
    for (int e = 0; e < 9; ++e) s.blocks.push_back(b(e / 3, e % 3));
  };
  for (int i = 0; i < N; ++i) {
    const bool pin = i == pinned;
    if (i > 0 && !pin && i - 1 != pinned) add(i - 1, -off[i - 1]);
    add(i, pin ? Eigen::Matrix3d::Identity() : diag[i]);
    if (i + 1 < N && !pin && i + 1 != pinned) add(i + 1, -off[i]);
    s.offsets.push_back(static_cast<int32_t>(s.columns.size()));
    s.scale.push_back(pin ? 0.0 : mass(i, 0));
  }
  return s;
}

}  // namespace

TEST(BlockSpdSolve, SolvesTheSystemAndKeepsPinnedRowsAtZero) {
  const ChainSystem s = chain(9, 30.0, 4, 7);
  const RowMat<double> b = random_matrix(9, 3, 8);
  Tape<double> tape;
  const Var<double> y = block_spd_solve(tape, s.view(), tape.constant(b.data(), 9, 3));
  const Eigen::Map<const Eigen::VectorXd> yv(y.value, 27);
  Eigen::VectorXd rhs(27);
  for (int i = 0; i < 9; ++i)
    for (int c = 0; c < 3; ++c) rhs[3 * i + c] = s.scale[i] * b(i, c);
  EXPECT_LT((s.dense() * yv - rhs).norm(), 1e-10 * rhs.norm());
  for (int c = 0; c < 3; ++c) EXPECT_EQ(y.value[3 * 4 + c], 0.0);
  // Stiff springs pass a common translation and hold back a relative one: with all rows moved
  // alike the free rows follow (the chain's two halves move rigidly), with one row moved alone
  // it keeps a fraction of its move.
  const ChainSystem free_chain = chain(6, 1e4, -1, 9);
  RowMat<double> shift = RowMat<double>::Zero(6, 3);
  shift.col(0).setConstant(1.0);
  const Var<double> moved = block_spd_solve(tape, free_chain.view(), tape.constant(shift.data(), 6, 3));
  for (int i = 0; i < 6; ++i) EXPECT_NEAR(moved.value[3 * i], 1.0, 1e-9);
  RowMat<double> poke = RowMat<double>::Zero(6, 3);
  poke(2, 1) = 1.0;
  const Var<double> held = block_spd_solve(tape, free_chain.view(), tape.constant(poke.data(), 6, 3));
  EXPECT_LT(held.value[3 * 2 + 1], 0.5);
  EXPECT_GT(held.value[3 * 2 + 1], 0.0);
}

TEST(BlockSpdSolve, RefusesMismatchedShapes) {
  const ChainSystem s = chain(4, 1.0, -1, 3);
  Tape<double> tape;
  const RowMat<double> b = random_matrix(5, 3, 4);
  EXPECT_THROW(block_spd_solve(tape, s.view(), tape.constant(b.data(), 5, 3)), std::exception);
  BlockSpd<double> short_scale = s.view();
  short_scale.scale = short_scale.scale.subspan(1);
  const RowMat<double> b4 = random_matrix(4, 3, 5);
  EXPECT_THROW(block_spd_solve(tape, short_scale, tape.constant(b4.data(), 4, 3)), std::exception);
}

GRADCHECK_TEST(BlockSpdSolve, ChainWithAPinnedRow) {
  const ChainSystem s = chain(7, 5.0, 2, 21);
  const auto f = [&](Tape<double>& t, const std::vector<Var<double>>& v) { return block_spd_solve(t, s.view(), v[0]); };
  expect_gradcheck(OpKind::BlockSpdSolve, f, {{random_matrix(7, 3, 22)}});
}

GRADCHECK_TEST(BlockSpdSolve, OneRow) {
  const ChainSystem s = chain(1, 5.0, -1, 23);
  const auto f = [&](Tape<double>& t, const std::vector<Var<double>>& v) { return block_spd_solve(t, s.view(), v[0]); };
  expect_gradcheck(OpKind::BlockSpdSolve, f, {{random_matrix(1, 3, 24)}});
}

TEST(BlockSpdSolve, SameBitsForAnyThreadCount) {
  const ChainSystem s = chain(40, 50.0, 5, 31);
  const RowMat<double> b = random_matrix(40, 3, 32);
  const int was = omp_get_max_threads();
  std::vector<double> out[2];
  for (int threads : {1, 2}) {
    omp_set_num_threads(threads);
    Tape<double> tape;
    const Var<double> y = block_spd_solve(tape, s.view(60, 1e-6), tape.constant(b.data(), 40, 3));
    out[threads - 1].assign(y.value, y.value + 120);
  }
  omp_set_num_threads(was);
  EXPECT_EQ(std::memcmp(out[0].data(), out[1].data(), sizeof(double) * 120), 0);
}

}  // namespace layersnet::ad::testing
