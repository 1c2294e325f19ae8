#pragma once
// float32 matrix products for the linear layers' forward and backward (autodiff/ops_dense.cpp):
//
//   C = C + A B   (or C = A B with `assign`)
//   A: (m, k), element (i, p) at a[i * a_row + p * a_col], so a row-major matrix and a
//      transposed one are both views (dW = dyᵀ x reads dy with a_row = 1, a_col = Cout);
//   B: (k, n) row-major with leading dimension ldb (rows of x, of W, or of Wᵀ);
//   C: (m, n) row-major with leading dimension ldc.
//
// Each C element is one chain of fused multiply-adds over p = 0, 1, ..., k-1 in order, started
// from C's value (or 0). The blocking over k stores and reloads the partial sum, which is exact,
// so an element's bits depend only on its own row of A, column of B and start value: not on m,
// n, the block sizes, where a row falls in a call, or the thread count.
//
// Kernels, chosen at run time (f32_gemm_kernel()); avx512 and avx2 run the same chains, so they
// give the same bits:
// - "avx512": 12 x 32 register blocks of zmm accumulators, when compiled with __AVX512F__
//   (-march=native on a CPU that has it). Debian 12's Eigen 3.4 runs its AVX-512 GEMM at
//   0.5-0.8x this kernel's rate on an AMD EPYC (Zen 5) and level with it on an Intel Xeon
//   (docs/decisions.md, "A float32 GEMM of our own", "The float32 GEMM of our own on AVX2").
// - "avx2": 6 x 16 register blocks of ymm accumulators, when compiled with __AVX2__ and __FMA__;
//   1.1-1.2x Eigen's AVX2 GEMM on an AMD EPYC, level with it on an Intel Xeon.
// - "eigen": Eigen's product, which the callers run themselves (autodiff/ops_dense.cpp); its
//   rounding depends on where a row falls in the call, so there the callers fix the row blocks.
// LAYERSNET_F32_GEMM=avx512|avx2|eigen picks one (for measurements; naming one the build lacks
// is an error).
#include <cstdint>

namespace layersnet::ad {

enum class F32GemmKernel { kEigen, kAvx2, kAvx512 };

bool f32_gemm_kernel_available(F32GemmKernel kernel);
// LAYERSNET_F32_GEMM if set (std::runtime_error naming the variable and the choices when it is
// unknown or unavailable), else the fastest available. Read once per process.
F32GemmKernel f32_gemm_kernel();
const char* f32_gemm_kernel_name(F32GemmKernel kernel);  // "avx512", "avx2" or "eigen"

// C (+)= A B as above with `kernel` (avx512 or avx2), on the calling thread; A must have a unit
// stride one way (a_row == 1 or a_col == 1). m, n, k >= 0; k = 0 leaves C (or zeroes it with
// `assign`). Throws std::logic_error where the build lacks the kernel, `kernel` is eigen, or A
// has no unit stride.
void gemm_f32(F32GemmKernel kernel, int64_t m, int64_t n, int64_t k, const float* a, int64_t a_row, int64_t a_col,
              const float* b, int64_t ldb, float* c, int64_t ldc, bool assign);

}  // namespace layersnet::ad
