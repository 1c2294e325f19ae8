// The conjugate gradients (autodiff/conjugate_gradients.h): they solve a block system, and give
// the same bits on any number of threads.
#include "autodiff/conjugate_gradients.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <vector>

namespace layersnet::ad {
namespace {

// A chain of rows (each coupled to its neighbours and to the row `far` ahead), symmetric and
// diagonally dominant: 3 × 3 blocks on a band, stored dense by row for the test's product.
struct BandSystem {
  int64_t rows, far;
  std::vector<double> diagonal, coupling;  // (rows) each; the off-diagonal blocks are −coupling · I
  BandSystem(int64_t n, unsigned seed) : rows(n), far(n / 3) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<double> u(0.5, 1.5);
    coupling.resize(static_cast<std::size_t>(n));
    for (auto& c : coupling) c = u(rng);
    diagonal.assign(static_cast<std::size_t>(n), 0.0);
    for (int64_t r = 0; r < n; ++r) diagonal[r] = 4 * u(rng) + 2 * (coupling[r] + coupling[(r + far) % n]) + 1;
  }
  // The row's neighbours r ± 1 and r ± far (cyclic), each weighted by the coupling of the pair.
  void multiply(const std::vector<double>& p, std::vector<double>& y, int64_t r0, int64_t r1) const {
    for (int64_t r = r0; r < r1; ++r)
      for (int c = 0; c < 3; ++c) {
        const int64_t next = (r + 1) % rows, prev = (r + rows - 1) % rows;
        const int64_t ahead = (r + far) % rows, behind = (r + rows - far) % rows;
        y[3 * r + c] = diagonal[r] * p[3 * r + c] - 0.5 * coupling[r] * p[3 * next + c] -
                       0.5 * coupling[prev] * p[3 * prev + c] - 0.5 * coupling[r] * p[3 * ahead + c] -
                       0.5 * coupling[behind] * p[3 * behind + c];
      }
  }
};

std::vector<double> solve_on(const BandSystem& a, const std::vector<double>& b, int threads, int iterations) {
  auto multiply = [&](const std::vector<double>& p, std::vector<double>& y, int64_t r0, int64_t r1) {
    a.multiply(p, y, r0, r1);
  };
  auto precondition = [&](const std::vector<double>& r, std::vector<double>& z, int64_t r0, int64_t r1) {
    for (int64_t k = 3 * r0; k < 3 * r1; ++k) z[k] = r[k] / a.diagonal[k / 3];
  };
  return conjugate_gradients(b, multiply, precondition, iterations, 1e-24, threads);
}

TEST(ConjugateGradients, SolvesTheSystemWithTheSameBitsOnAnyThreadCount) {
  const BandSystem a(3000, 7);  // twelve chunks of rows
  std::mt19937 rng(8);
  std::normal_distribution<double> n01;
  std::vector<double> b(3 * 3000);
  for (auto& v : b) v = n01(rng);
  const std::vector<double> one = solve_on(a, b, 1, 200);
  std::vector<double> ax(b.size());
  a.multiply(one, ax, 0, a.rows);
  double residual = 0, norm = 0;
  for (std::size_t k = 0; k < b.size(); ++k) residual += (ax[k] - b[k]) * (ax[k] - b[k]), norm += b[k] * b[k];
  EXPECT_LT(std::sqrt(residual / norm), 1e-10);
  for (int threads : {2, 3, 5}) EXPECT_EQ(solve_on(a, b, threads, 200), one) << threads << " threads";
  // Stopped early too: a few iterations are the same bits on two threads.
  EXPECT_EQ(solve_on(a, b, 2, 7), solve_on(a, b, 1, 7));
}

// Called from inside a parallel region (training's samples), each call runs on the one thread
// OpenMP gives it, and gives the one-thread answer.
TEST(ConjugateGradients, InsideAParallelRegionEachCallIsOneThread) {
  const BandSystem a(3000, 10);
  std::vector<double> b(3 * 3000, 1.0);
  const std::vector<double> one = solve_on(a, b, 1, 40);
  std::vector<std::vector<double>> inside(2);
#pragma omp parallel for num_threads(2)
  for (int k = 0; k < 2; ++k) inside[k] = solve_on(a, b, 2, 40);
  EXPECT_EQ(inside[0], one);
  EXPECT_EQ(inside[1], one);
}

TEST(ConjugateGradients, FewerRowsThanThreadsAndNoRows) {
  const BandSystem a(5, 9);
  std::vector<double> b(15, 1.0);
  EXPECT_EQ(solve_on(a, b, 4, 50), solve_on(a, b, 1, 50));
  EXPECT_TRUE(solve_on(BandSystem(0, 1), {}, 2, 10).empty());
}

}  // namespace
}  // namespace layersnet::ad
