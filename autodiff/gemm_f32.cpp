#include "autodiff/gemm_f32.h"

#include <algorithm>
#include <array>
#include <cstdlib>
#include <stdexcept>
#include <string>
#include <utility>

#ifdef __AVX512F__
#include <immintrin.h>
#endif

namespace layersnet::ad {

namespace {

#ifdef __AVX512F__
// Rows of C per register block, columns per block (two zmm), and the blocks over k and m that
// keep a 32-column strip of B (kKBlock x 128 bytes) in L1 and kMBlock rows of A in L2.
constexpr int kRows = 12;
constexpr int64_t kKBlock = 256, kMBlock = 240;

// C[0..R) x [0..16 V) (+)= A[0..R) x [0..kb) * B[0..kb) x [0..16 V), columns masked by m0/m1.
// A's element (r, p) is a[p * lda + r] when ATransposed, a[r * lda + p] otherwise.
template <int R, int V, bool ATransposed>
void block(int64_t kb, const float* a, int64_t lda, const float* b, int64_t ldb, float* c, int64_t ldc, bool load_c,
           __mmask16 m0, __mmask16 m1) {
  __m512 c0[R], c1[V == 2 ? R : 1];
#pragma GCC unroll 12
  for (int r = 0; r < R; ++r) {
    c0[r] = load_c ? _mm512_maskz_loadu_ps(m0, c + r * ldc) : _mm512_setzero_ps();
    if constexpr (V == 2) c1[r] = load_c ? _mm512_maskz_loadu_ps(m1, c + r * ldc + 16) : _mm512_setzero_ps();
  }
  for (int64_t p = 0; p < kb; ++p, a += ATransposed ? lda : 1, b += ldb) {
    const __m512 b0 = _mm512_maskz_loadu_ps(m0, b);
    const __m512 b1 = V == 2 ? _mm512_maskz_loadu_ps(m1, b + 16) : b0;
#pragma GCC unroll 12
    for (int r = 0; r < R; ++r) {
      const __m512 av = _mm512_set1_ps(ATransposed ? a[r] : a[r * lda]);
      c0[r] = _mm512_fmadd_ps(av, b0, c0[r]);
      if constexpr (V == 2) c1[r] = _mm512_fmadd_ps(av, b1, c1[r]);
    }
  }
#pragma GCC unroll 12
  for (int r = 0; r < R; ++r) {
    _mm512_mask_storeu_ps(c + r * ldc, m0, c0[r]);
    if constexpr (V == 2) _mm512_mask_storeu_ps(c + r * ldc + 16, m1, c1[r]);
  }
}

using BlockFn = void (*)(int64_t, const float*, int64_t, const float*, int64_t, float*, int64_t, bool, __mmask16,
                         __mmask16);

template <int V, bool ATransposed, int... R>
constexpr std::array<BlockFn, sizeof...(R)> block_table(std::integer_sequence<int, R...>) {
  return {&block<R + 1, V, ATransposed>...};
}

template <bool ATransposed>
void gemm_avx512(int64_t m, int64_t n, int64_t k, const float* a, int64_t lda, const float* b, int64_t ldb, float* c,
                 int64_t ldc, bool assign) {
  static constexpr auto one = block_table<1, ATransposed>(std::make_integer_sequence<int, kRows>{});
  static constexpr auto two = block_table<2, ATransposed>(std::make_integer_sequence<int, kRows>{});
  auto at = [&](int64_t i, int64_t p) { return ATransposed ? a + p * lda + i : a + i * lda + p; };
  for (int64_t mb = 0; mb < m; mb += kMBlock) {
    const int64_t m1 = std::min(m, mb + kMBlock);
    for (int64_t k0 = 0; k0 < k; k0 += kKBlock) {
      const int64_t kb = std::min(kKBlock, k - k0);
      const bool load_c = k0 > 0 || !assign;
      for (int64_t j0 = 0; j0 < n; j0 += 32) {
        const int64_t cols = std::min<int64_t>(32, n - j0);
        const auto mask0 = static_cast<__mmask16>(cols >= 16 ? 0xFFFF : (1u << cols) - 1);
        const auto mask1 = static_cast<__mmask16>(cols >= 32 ? 0xFFFF : cols > 16 ? (1u << (cols - 16)) - 1 : 0);
        const auto& table = cols > 16 ? two : one;
        for (int64_t i0 = mb; i0 < m1; i0 += kRows) {
          const auto rows = static_cast<int>(std::min<int64_t>(kRows, m1 - i0));
          table[rows - 1](kb, at(i0, k0), lda, b + k0 * ldb + j0, ldb, c + i0 * ldc + j0, ldc, load_c, mask0, mask1);
        }
      }
    }
  }
  if (k == 0 && assign)
    for (int64_t i = 0; i < m; ++i) std::fill(c + i * ldc, c + i * ldc + n, 0.0f);
}
#endif

F32GemmKernel choose_kernel() {
  const char* env = std::getenv("LAYERSNET_F32_GEMM");
  if (env && *env) {
    const std::string name = env;
    F32GemmKernel k;
    if (name == "avx512") k = F32GemmKernel::kAvx512;
    else if (name == "eigen") k = F32GemmKernel::kEigen;
    else
      throw std::runtime_error("LAYERSNET_F32_GEMM=" + name + ": unknown float32 GEMM kernel; choose avx512 or eigen");
    if (!f32_gemm_kernel_available(k))
      throw std::runtime_error("LAYERSNET_F32_GEMM=" + name +
                               ": this build has no such kernel (it needs AVX-512F at compile time: build with "
                               "-DLAYERSNET_NATIVE=ON on a CPU that has it); unset the variable to use eigen");
    return k;
  }
  return f32_gemm_kernel_available(F32GemmKernel::kAvx512) ? F32GemmKernel::kAvx512 : F32GemmKernel::kEigen;
}

}  // namespace

bool f32_gemm_kernel_available(F32GemmKernel kernel) {
#ifdef __AVX512F__
  (void)kernel;
  return true;
#else
  return kernel == F32GemmKernel::kEigen;
#endif
}

F32GemmKernel f32_gemm_kernel() {
  static const F32GemmKernel kernel = choose_kernel();
  return kernel;
}

const char* f32_gemm_kernel_name(F32GemmKernel kernel) { return kernel == F32GemmKernel::kAvx512 ? "avx512" : "eigen"; }

void gemm_f32(int64_t m, int64_t n, int64_t k, const float* a, int64_t a_row, int64_t a_col, const float* b,
              int64_t ldb, float* c, int64_t ldc, bool assign) {
#ifdef __AVX512F__
  if (m <= 0 || n <= 0) return;
  if (a_col == 1) return gemm_avx512<false>(m, n, k, a, a_row, b, ldb, c, ldc, assign);
  if (a_row == 1) return gemm_avx512<true>(m, n, k, a, a_col, b, ldb, c, ldc, assign);
  throw std::logic_error("gemm_f32: A's strides are " + std::to_string(a_row) + " and " + std::to_string(a_col) +
                         "; one must be 1");
#else
  (void)m, (void)n, (void)k, (void)a, (void)a_row, (void)a_col, (void)b, (void)ldb, (void)c, (void)ldc, (void)assign;
  throw std::logic_error("gemm_f32: this build has no avx512 kernel (it needs AVX-512F at compile time)");
#endif
}

}  // namespace layersnet::ad
