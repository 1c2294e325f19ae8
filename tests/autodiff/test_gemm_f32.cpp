// The float32 kernels of autodiff/gemm_f32.h (avx512 and avx2, each where the build has it):
// every output is the fused multiply-add chain over k in order from its start value, bit for
// bit, whatever the shape, the tails, the k and m blocks or the layout of A; and the linear
// layers that run on the chosen one agree with double precision.
#include "autodiff/gemm_f32.h"
#include "autodiff/ops_dense.h"
#include "autodiff/tape.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <cstring>
#include <random>
#include <string>
#include <vector>

namespace {

using namespace layersnet::ad;

std::vector<float> random_values(std::size_t n, std::mt19937& rng) {
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  std::vector<float> v(n);
  for (float& x : v) x = u(rng);
  return v;
}

bool same_bits(float a, float b) { return std::memcmp(&a, &b, sizeof a) == 0; }

// C (m, n) with leading dimension ldc, A (m, k) read through (a_row, a_col), B (k, n) with ldb:
// the chain the kernel promises, one std::fma at a time.
float chain(int64_t i, int64_t j, int64_t k, const std::vector<float>& a, int64_t a_row, int64_t a_col,
            const std::vector<float>& b, int64_t ldb, float start) {
  float acc = start;
  for (int64_t p = 0; p < k; ++p) acc = std::fma(a[i * a_row + p * a_col], b[p * ldb + j], acc);
  return acc;
}

class GemmF32 : public ::testing::TestWithParam<F32GemmKernel> {
 protected:
  void SetUp() override {
    if (!f32_gemm_kernel_available(GetParam()))
      GTEST_SKIP() << "this build has no " << f32_gemm_kernel_name(GetParam()) << " float32 kernel";
  }
};

TEST_P(GemmF32, EveryOutputIsTheOrderedFmaChainForAnyShapeAndLayout) {
  std::mt19937 rng(7);
  // Row counts through the 6- and 12-row register blocks and the 240-row m block, columns
  // through the 8-, 16- and 32-lane tails, k through the 256-deep k block.
  for (const int64_t m : {1, 5, 6, 7, 12, 13, 25, 250})
    for (const int64_t n : {1, 7, 8, 9, 15, 16, 17, 24, 32, 45})
      for (const int64_t k : {0, 1, 7, 300})
        for (const bool transposed_a : {false, true})
          for (const bool assign : {false, true}) {
            const int64_t lda = (transposed_a ? m : k) + 3, ldb = n + 2, ldc = n + 5;  // padded leading dimensions
            const int64_t a_row = transposed_a ? 1 : lda, a_col = transposed_a ? lda : 1;
            const auto a = random_values(static_cast<std::size_t>((transposed_a ? k : m) * lda + 1), rng);
            const auto b = random_values(static_cast<std::size_t>(k * ldb + 1), rng);
            auto c = random_values(static_cast<std::size_t>(m * ldc), rng);
            const auto start = c;
            gemm_f32(GetParam(), m, n, k, a.data(), a_row, a_col, b.data(), ldb, c.data(), ldc, assign);
            for (int64_t i = 0; i < m; ++i)
              for (int64_t j = 0; j < ldc; ++j) {
                const float before = start[i * ldc + j], got = c[i * ldc + j];
                if (j >= n) {  // padding is left alone
                  ASSERT_TRUE(same_bits(got, before)) << "m " << m << " n " << n << " k " << k << " wrote padding";
                  continue;
                }
                const float want = chain(i, j, k, a, a_row, a_col, b, ldb, assign ? 0.0f : before);
                ASSERT_TRUE(same_bits(got, want)) << "m " << m << " n " << n << " k " << k << " transposed A "
                                                  << transposed_a << " assign " << assign << " at (" << i << ", " << j
                                                  << "): " << got << " against " << want;
              }
          }
}

TEST_P(GemmF32, ARowGivesTheSameBitsWhereverItFallsInTheCall) {
  std::mt19937 rng(11);
  const int64_t m = 37, n = 40, k = 270;
  const auto a = random_values(static_cast<std::size_t>(m * k), rng);
  const auto b = random_values(static_cast<std::size_t>(k * n), rng);
  std::vector<float> whole(static_cast<std::size_t>(m * n)), part(static_cast<std::size_t>(5 * n));
  gemm_f32(GetParam(), m, n, k, a.data(), k, 1, b.data(), n, whole.data(), n, true);
  gemm_f32(GetParam(), 5, n, k, a.data() + 30 * k, k, 1, b.data(), n, part.data(), n, true);  // rows 30..34 alone
  for (int64_t i = 0; i < 5; ++i)
    for (int64_t j = 0; j < n; ++j) ASSERT_TRUE(same_bits(part[i * n + j], whole[(30 + i) * n + j])) << i << ", " << j;
}

TEST_P(GemmF32, AWithoutAUnitStrideIsRefused) {
  std::vector<float> a(16), b(16), c(16);
  EXPECT_THROW(gemm_f32(GetParam(), 2, 2, 2, a.data(), 2, 3, b.data(), 2, c.data(), 2, true), std::logic_error);
}

INSTANTIATE_TEST_SUITE_P(Kernels, GemmF32, ::testing::Values(F32GemmKernel::kAvx512, F32GemmKernel::kAvx2),
                         [](const auto& info) { return std::string(f32_gemm_kernel_name(info.param)); });

TEST(GemmF32Kernels, EigenIsNotAKernelOfOurOwn) {
  std::vector<float> a(4), b(4), c(4);
  EXPECT_THROW(gemm_f32(F32GemmKernel::kEigen, 2, 2, 2, a.data(), 2, 1, b.data(), 2, c.data(), 2, true),
               std::logic_error);
}

// The chosen kernel is the fastest the build has; Eigen only where it has neither.
TEST(GemmF32Kernels, TheFastestAvailableKernelIsChosen) {
  if (std::getenv("LAYERSNET_F32_GEMM")) GTEST_SKIP() << "LAYERSNET_F32_GEMM picks the kernel";
  const F32GemmKernel want = f32_gemm_kernel_available(F32GemmKernel::kAvx512) ? F32GemmKernel::kAvx512
                             : f32_gemm_kernel_available(F32GemmKernel::kAvx2) ? F32GemmKernel::kAvx2
                                                                                : F32GemmKernel::kEigen;
  EXPECT_EQ(f32_gemm_kernel(), want);
}

// The linear layer's forward and backward on a float tape (which run on the chosen kernel)
// against the same on a double tape, within float32's rounding of 268-term sums.
TEST(GemmF32Linear, FloatLinearMatchesDoubleForwardAndBackward) {
  std::mt19937 rng(3);
  const int64_t N = 700, cin = 268, cout = 70;
  const auto xs = random_values(static_cast<std::size_t>(N * cin), rng);
  const auto ws = random_values(static_cast<std::size_t>(cout * cin), rng);
  const auto bs = random_values(static_cast<std::size_t>(cout), rng);
  auto run = [&](auto zero) {
    using T = decltype(zero);
    const std::vector<T> xv(xs.begin(), xs.end()), wv(ws.begin(), ws.end()), bv(bs.begin(), bs.end());
    Tape<T> tape;
    Var<T> x = tape.leaf(xv.data(), N, cin), W = tape.leaf(wv.data(), cout, cin), b = tape.leaf(bv.data(), 1, cout);
    Var<T> y = linear_relu(tape, x, W, b);
    tape.backward(sum_all(tape, mul(tape, y, y)));
    std::vector<double> out;
    for (int64_t i = 0; i < y.size(); ++i) out.push_back(static_cast<double>(y.value[i]));
    for (int64_t i = 0; i < x.size(); ++i) out.push_back(static_cast<double>(x.grad[i]));
    for (int64_t i = 0; i < W.size(); ++i) out.push_back(static_cast<double>(W.grad[i]));
    return out;
  };
  const auto f = run(0.0f), d = run(0.0);
  ASSERT_EQ(f.size(), d.size());
  double worst = 0, scale = 0;
  for (std::size_t i = 0; i < f.size(); ++i) {
    worst = std::max(worst, std::abs(f[i] - d[i]));
    scale = std::max(scale, std::abs(d[i]));
  }
  EXPECT_LT(worst, 2e-5 * scale) << "largest difference " << worst << " of values up to " << scale;
}

}  // namespace
