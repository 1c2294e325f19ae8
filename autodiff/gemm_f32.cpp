#include "autodiff/gemm_f32.h"

#include <algorithm>
#include <array>
#include <cstdlib>
#include <stdexcept>
#include <string>
#include <utility>

#if defined(__AVX2__) && defined(__FMA__)
#define LAYERSNET_HAS_AVX2_GEMM 1
#endif
#ifdef __AVX512F__
#define LAYERSNET_HAS_AVX512_GEMM 1
#endif
#if defined(LAYERSNET_HAS_AVX2_GEMM) || defined(LAYERSNET_HAS_AVX512_GEMM)
#define LAYERSNET_HAS_OWN_GEMM 1
#include <immintrin.h>
#endif

namespace layersnet::ad {

namespace {

#ifdef LAYERSNET_HAS_OWN_GEMM
// One instruction set's vectors for the shared kernel below. kRows x 2 accumulators, two B
// vectors and one broadcast must fit the register file: 12 x 2 + 3 of 32 zmm, 6 x 2 + 3 of 16 ymm.
#ifdef LAYERSNET_HAS_AVX512_GEMM
struct Avx512 {
  static constexpr int kRows = 12, kLanes = 16;
  using Vec = __m512;
  using Mask = __mmask16;
  static Mask mask(int64_t lanes) {  // the first min(max(lanes, 0), 16) lanes
    return lanes >= 16 ? Mask(0xFFFF) : lanes <= 0 ? Mask(0) : static_cast<Mask>((1u << lanes) - 1);
  }
  static Vec zero() { return _mm512_setzero_ps(); }
  static Vec broadcast(float x) { return _mm512_set1_ps(x); }
  static Vec fmadd(Vec a, Vec b, Vec c) { return _mm512_fmadd_ps(a, b, c); }
  static Vec load(const float* p) { return _mm512_loadu_ps(p); }
  static Vec load(const float* p, Mask m) { return _mm512_maskz_loadu_ps(m, p); }
  static void store(float* p, Vec v) { _mm512_storeu_ps(p, v); }
  static void store(float* p, Vec v, Mask m) { _mm512_mask_storeu_ps(p, m, v); }
};
#endif

#ifdef LAYERSNET_HAS_AVX2_GEMM
struct Avx2 {
  static constexpr int kRows = 6, kLanes = 8;
  using Vec = __m256;
  using Mask = __m256i;
  static Mask mask(int64_t lanes) {  // the first min(max(lanes, 0), 8) lanes: a window on -1 x 8, 0 x 8
    static constexpr int32_t ramp[16] = {-1, -1, -1, -1, -1, -1, -1, -1, 0, 0, 0, 0, 0, 0, 0, 0};
    return _mm256_loadu_si256(reinterpret_cast<const __m256i*>(ramp + 8 - std::clamp<int64_t>(lanes, 0, 8)));
  }
  static Vec zero() { return _mm256_setzero_ps(); }
  static Vec broadcast(float x) { return _mm256_set1_ps(x); }
  static Vec fmadd(Vec a, Vec b, Vec c) { return _mm256_fmadd_ps(a, b, c); }
  static Vec load(const float* p) { return _mm256_loadu_ps(p); }
  static Vec load(const float* p, Mask m) { return _mm256_maskload_ps(p, m); }
  static void store(float* p, Vec v) { _mm256_storeu_ps(p, v); }
  static void store(float* p, Vec v, Mask m) { _mm256_maskstore_ps(p, m, v); }
};
#endif

// Blocks over k and m that keep a strip of B (kKBlock rows of 2 vectors) in L1 and kMBlock rows
// of A in L2; kMBlock is a multiple of both kernels' kRows.
constexpr int64_t kKBlock = 256, kMBlock = 240;

// C[0..R) x [0..V vectors) (+)= A[0..R) x [0..kb) * B[0..kb) x [0..V vectors). Full: every
// column present (plain loads and stores); else the lanes masked by m0 and m1.
// A's element (r, p) is a[p * lda + r] when ATransposed, a[r * lda + p] otherwise.
template <class Isa, int R, int V, bool Full, bool ATransposed>
void block(int64_t kb, const float* a, int64_t lda, const float* b, int64_t ldb, float* c, int64_t ldc, bool load_c,
           typename Isa::Mask m0, typename Isa::Mask m1) {
  using Vec = typename Isa::Vec;
  constexpr int L = Isa::kLanes;
  auto load = [&](const float* p, typename Isa::Mask m) { return Full ? Isa::load(p) : Isa::load(p, m); };
  Vec c0[R], c1[V == 2 ? R : 1];
#pragma GCC unroll 12
  for (int r = 0; r < R; ++r) {
    c0[r] = load_c ? load(c + r * ldc, m0) : Isa::zero();
    if constexpr (V == 2) c1[r] = load_c ? load(c + r * ldc + L, m1) : Isa::zero();
  }
  for (int64_t p = 0; p < kb; ++p, a += ATransposed ? lda : 1, b += ldb) {
    const Vec b0 = load(b, m0);
    const Vec b1 = V == 2 ? load(b + L, m1) : b0;
#pragma GCC unroll 12
    for (int r = 0; r < R; ++r) {
      const Vec av = Isa::broadcast(ATransposed ? a[r] : a[r * lda]);
      c0[r] = Isa::fmadd(av, b0, c0[r]);
      if constexpr (V == 2) c1[r] = Isa::fmadd(av, b1, c1[r]);
    }
  }
#pragma GCC unroll 12
  for (int r = 0; r < R; ++r) {
    if constexpr (Full) Isa::store(c + r * ldc, c0[r]);
    else Isa::store(c + r * ldc, c0[r], m0);
    if constexpr (V == 2) {
      if constexpr (Full) Isa::store(c + r * ldc + L, c1[r]);
      else Isa::store(c + r * ldc + L, c1[r], m1);
    }
  }
}

template <class Isa>
using BlockFn = void (*)(int64_t, const float*, int64_t, const float*, int64_t, float*, int64_t, bool,
                         typename Isa::Mask, typename Isa::Mask);

// Block functions for 1..kRows rows.
template <class Isa, int V, bool Full, bool ATransposed, int... R>
constexpr std::array<BlockFn<Isa>, sizeof...(R)> block_table(std::integer_sequence<int, R...>) {
  return {&block<Isa, R + 1, V, Full, ATransposed>...};
}

template <class Isa, bool ATransposed>
void gemm(int64_t m, int64_t n, int64_t k, const float* a, int64_t lda, const float* b, int64_t ldb, float* c,
          int64_t ldc, bool assign) {
  constexpr int L = Isa::kLanes;
  constexpr auto rows = std::make_integer_sequence<int, Isa::kRows>{};
  static constexpr auto full = block_table<Isa, 2, true, ATransposed>(rows);
  static constexpr auto two = block_table<Isa, 2, false, ATransposed>(rows);
  static constexpr auto one = block_table<Isa, 1, false, ATransposed>(rows);
  auto at = [&](int64_t i, int64_t p) { return ATransposed ? a + p * lda + i : a + i * lda + p; };
  for (int64_t mb = 0; mb < m; mb += kMBlock) {
    const int64_t m1 = std::min(m, mb + kMBlock);
    for (int64_t k0 = 0; k0 < k; k0 += kKBlock) {
      const int64_t kb = std::min(kKBlock, k - k0);
      const bool load_c = k0 > 0 || !assign;
      for (int64_t j0 = 0; j0 < n; j0 += 2 * L) {
        const int64_t cols = std::min<int64_t>(2 * L, n - j0);
        const auto mask0 = Isa::mask(cols), mask1 = Isa::mask(cols - L);
        const auto& table = cols == 2 * L ? full : cols > L ? two : one;
        for (int64_t i0 = mb; i0 < m1; i0 += Isa::kRows) {
          const auto r = static_cast<int>(std::min<int64_t>(Isa::kRows, m1 - i0));
          table[r - 1](kb, at(i0, k0), lda, b + k0 * ldb + j0, ldb, c + i0 * ldc + j0, ldc, load_c, mask0, mask1);
        }
      }
    }
  }
  if (k == 0 && assign)
    for (int64_t i = 0; i < m; ++i) std::fill(c + i * ldc, c + i * ldc + n, 0.0f);
}

template <class Isa>
void gemm_unit_stride(int64_t m, int64_t n, int64_t k, const float* a, int64_t a_row, int64_t a_col, const float* b,
                      int64_t ldb, float* c, int64_t ldc, bool assign) {
  if (a_col == 1) return gemm<Isa, false>(m, n, k, a, a_row, b, ldb, c, ldc, assign);
  if (a_row == 1) return gemm<Isa, true>(m, n, k, a, a_col, b, ldb, c, ldc, assign);
  throw std::logic_error("gemm_f32: A's strides are " + std::to_string(a_row) + " and " + std::to_string(a_col) +
                         "; one must be 1");
}
#endif

F32GemmKernel choose_kernel() {
  const char* env = std::getenv("LAYERSNET_F32_GEMM");
  if (env && *env) {
    const std::string name = env;
    F32GemmKernel k;
    if (name == "avx512") k = F32GemmKernel::kAvx512;
    else if (name == "avx2") k = F32GemmKernel::kAvx2;
    else if (name == "eigen") k = F32GemmKernel::kEigen;
    else
      throw std::runtime_error("LAYERSNET_F32_GEMM=" + name +
                               ": unknown float32 GEMM kernel; choose avx512, avx2 or eigen");
    if (!f32_gemm_kernel_available(k))
      throw std::runtime_error("LAYERSNET_F32_GEMM=" + name +
                               ": this build has no such kernel (avx512 needs AVX-512F at compile time, avx2 needs "
                               "AVX2 and FMA: build with -DLAYERSNET_NATIVE=ON on a CPU that has them); unset the "
                               "variable to use the fastest this build has");
    return k;
  }
  for (const F32GemmKernel k : {F32GemmKernel::kAvx512, F32GemmKernel::kAvx2})
    if (f32_gemm_kernel_available(k)) return k;
  return F32GemmKernel::kEigen;
}

}  // namespace

bool f32_gemm_kernel_available(F32GemmKernel kernel) {
  switch (kernel) {
    case F32GemmKernel::kEigen:
      return true;
    case F32GemmKernel::kAvx2:
#ifdef LAYERSNET_HAS_AVX2_GEMM
      return true;
#else
      return false;
#endif
    case F32GemmKernel::kAvx512:
#ifdef LAYERSNET_HAS_AVX512_GEMM
      return true;
#else
      return false;
#endif
  }
  return false;
}

F32GemmKernel f32_gemm_kernel() {
  static const F32GemmKernel kernel = choose_kernel();
  return kernel;
}

const char* f32_gemm_kernel_name(F32GemmKernel kernel) {
  switch (kernel) {
    case F32GemmKernel::kAvx512:
      return "avx512";
    case F32GemmKernel::kAvx2:
      return "avx2";
    case F32GemmKernel::kEigen:
      break;
  }
  return "eigen";
}

void gemm_f32(F32GemmKernel kernel, int64_t m, int64_t n, int64_t k, const float* a, int64_t a_row, int64_t a_col,
              const float* b, int64_t ldb, float* c, int64_t ldc, bool assign) {
  if (!f32_gemm_kernel_available(kernel) || kernel == F32GemmKernel::kEigen)
    throw std::logic_error(std::string("gemm_f32: this build has no ") + f32_gemm_kernel_name(kernel) +
                           " kernel of its own");
  if (m <= 0 || n <= 0) return;
#ifdef LAYERSNET_HAS_AVX512_GEMM
  if (kernel == F32GemmKernel::kAvx512)
    return gemm_unit_stride<Avx512>(m, n, k, a, a_row, a_col, b, ldb, c, ldc, assign);
#endif
#ifdef LAYERSNET_HAS_AVX2_GEMM
  if (kernel == F32GemmKernel::kAvx2) return gemm_unit_stride<Avx2>(m, n, k, a, a_row, a_col, b, ldb, c, ldc, assign);
#endif
  (void)k, (void)a, (void)a_row, (void)a_col, (void)b, (void)ldb, (void)c, (void)ldc, (void)assign;
}

}  // namespace layersnet::ad
