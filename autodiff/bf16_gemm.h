#pragma once
// bfloat16 matrix products for inference: out = x Wᵀ + b (optionally ReLU) with x and W
// rounded to bfloat16 and the products accumulated in float32 (AVX-512 BF16
// `_mm512_dpbf16_ps`). Used by linear / linear_relu (autodiff/ops_dense.h) when the tape's
// matmul precision is MatmulPrecision::kBFloat16 and the tape is not recording.
//
// Shapes (as linear): x: (N, Cin) row-major; W: (Cout, Cin) [torch layout]; b: (Cout) or
// null; out: (N, Cout) row-major. Any N >= 0, Cin >= 1 (odd Cin is padded with a zero
// column), any Cout >= 1 (tails handled by masked stores).
//
// Rounding: float -> bfloat16 is round-to-nearest-even, denormal inputs become (signed)
// zero and NaN stays a quiet NaN (what VCVTNE2PS2BF16 does). Every product of two bf16
// values is exact in float, so each step of the accumulation is one float rounding:
//   acc = b_j;  for each pair p = (2k, 2k+1):  acc += x_{2k+1} w_{2k+1};  acc += x_{2k} w_{2k}
// (the order of Intel's VDPBF16PS pseudo-code, kept by the scalar path too).
// Error against the float product: each input has relative error <= u = 2^-8 (8
// significant bits), so |y_bf16 - y_float| <= (2u + u²) Σ_k |x_k w_k| + float accumulation
// error (about Cin 2^-24 Σ_k |x_k w_k|): relative error ~ 2^-7 of Σ|x w| at worst, far less
// on average (errors of random sign).
//
// Kernels, chosen at run time (bf16_kernel()):
// - "amx-bf16": Intel AMX tiles (TDPBF16PS, 16 x 16 float outputs per instruction), on CPUs
//   that have AMX-TILE, AMX-BF16 and AVX-512 BF16 and whose kernel grants the tile state
//   (Linux >= 5.16). Compiled on every x86-64 build, used only where the CPU has it. Each
//   output sums the same bf16 products in 32-channel blocks; the tile unit's internal order
//   of those additions is not VDPBF16PS's, so it may differ from the other two in the last
//   bits (within the bound below; tests/autodiff/test_bf16.cpp).
// - "avx512-bf16": VDPBF16PS, when compiled with __AVX512BF16__ (-march=native on a CPU that
//   has it).
// - "scalar reference": the same rounding and order as avx512-bf16, on any CPU.
// The best available one runs; LAYERSNET_BF16_KERNEL=amx-bf16|avx512-bf16|scalar picks another
// (for measurements; naming one the CPU lacks is an error). Rows are independent, so results
// do not depend on the thread count.
//
// Packed weights and the cache: W is packed once into the VNNI-pair layout (for every group
// of 16 output columns and every pair of input channels, 32 bf16 values
// [w_j,2k, w_j,2k+1]_{j=0..15}; columns and the odd channel padded with zeros).
// bf16_cached_weights() keeps the packed form in a process-wide cache keyed on the weight
// pointer and shape, and VALIDATED by comparing W bitwise with the float copy taken at
// packing time: a weight changed in place (optimizer step, checkpoint load) or a new buffer
// at a recycled address is repacked, so callers never invalidate anything. The comparison
// reads Cout x Cin floats, 1/N of the product's work. The cache is guarded by a mutex
// (lookups happen once per linear call, outside the parallel region) and holds at most
// kBf16CacheEntries weights (then it is emptied; entries in use stay alive via shared_ptr).
#include "autodiff/tape.h"

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace layersnet::ad {

// linear / linear_relu use bf16 only when Cin >= this and Cout >= this (see ops_dense.h).
constexpr int64_t kBf16MinChannels = 16;

// "float32" | "fp32" | "bf16" | "bfloat16" -> MatmulPrecision; throws naming the choices.
MatmulPrecision parse_matmul_precision(const std::string& text);

enum class Bf16Kernel { kScalar, kAvx512, kAmx };

// Whether this build on this CPU can run `kernel` (the scalar one always can).
bool bf16_kernel_available(Bf16Kernel kernel);
// The kernel bf16_linear_forward runs: LAYERSNET_BF16_KERNEL if set (std::runtime_error naming
// the variable and the choices when unknown or unavailable), else the fastest available.
Bf16Kernel bf16_kernel();
// "amx-bf16", "avx512-bf16" or "scalar reference".
const char* bf16_kernel_name(Bf16Kernel kernel);
const char* bf16_kernel_name();  // of bf16_kernel()

// True when bf16_kernel() is a vector kernel; false for the scalar one.
bool bf16_available();

// True where the bf16 products out-run float32 ones: the AMX kernel, or the AVX-512 BF16 kernel on
// an AMD core. An Intel core without usable AMX (e.g. under a hypervisor that hides the tiles)
// issues VDPBF16PS at a quarter of the FMA's rate, half its multiply-adds a second
// (docs/decisions.md, "bf16 products only where they out-run float32"). `simulate
// --precision auto` takes bf16 only here.
bool bf16_outruns_float32();

// One core's multiply-adds per second (10⁹) in a loop of independent VDPBF16PS and of
// VFMADD231PS on 512-bit registers, best of `rounds` (about 5 ms each); 0 where the build
// lacks AVX-512 BF16. For `bench linear`: the instructions' own rates, free of memory.
struct DotRates {
  double bf16_gmacs = 0;
  double fma_gmacs = 0;
};
DotRates measure_dot_rates(int rounds = 5);

// float <-> bfloat16 bits (rounding as above).
uint16_t float_to_bf16(float f);
float bf16_to_float(uint16_t h);
// The value of f after rounding to bfloat16.
inline float round_to_bf16(float f) { return bf16_to_float(float_to_bf16(f)); }

// W (Cout, Cin) in the VNNI-pair layout: data[((g * pairs) + p) * 32 + 2 j + e] =
// bf16(W[16 g + j][2 p + e]), zero outside W. `source` is the float W it was made from.
struct Bf16PackedWeights {
  int64_t cout = 0, cin = 0;
  int64_t pairs = 0;   // ceil(Cin / 2)
  int64_t groups = 0;  // ceil(Cout / 16)
  std::vector<uint16_t> data;  // groups * pairs * 32
  std::vector<float> source;   // Cout * Cin (the cache's validation copy)
  // The same layout with each group's pairs padded with zeros to tile_pairs (a multiple of
  // 16: one AMX tile holds 16 pairs of 16 columns); made only where the AMX kernel can run.
  int64_t tile_pairs = 0;
  std::vector<uint16_t> tiles;  // groups * tile_pairs * 32
};

// Packs W: (Cout, Cin).
std::shared_ptr<const Bf16PackedWeights> bf16_pack_weights(const float* W, int64_t cout, int64_t cin);

// The cached packed form of W (packs on a miss or when W's values changed).
constexpr std::size_t kBf16CacheEntries = 512;
std::shared_ptr<const Bf16PackedWeights> bf16_cached_weights(const float* W, int64_t cout, int64_t cin);

struct Bf16CacheStats {
  int64_t packs = 0;    // packings done by bf16_cached_weights since the last clear
  int64_t hits = 0;     // lookups served without packing
  int64_t entries = 0;  // weights held now
};
Bf16CacheStats bf16_weight_cache_stats();
void bf16_clear_weight_cache();

// out = x Wᵀ + b (then max(., 0) with relu). x: (N, Cin); w packed from (Cout, Cin) with
// Cin = x's columns; b: (Cout) or null; out: (N, Cout). Rows spread over the OpenMP
// threads (serial for small N or inside a parallel region). No allocation after the first
// call on a thread (a per-thread bf16 row buffer grows once). `kernel` must be available.
void bf16_linear_forward(const float* x, int64_t n, int64_t cin, const Bf16PackedWeights& w, const float* b,
                         bool relu, float* out, Bf16Kernel kernel = bf16_kernel());

// The scalar reference path, whatever the CPU (tests compare the kernel against it).
void bf16_linear_forward_scalar(const float* x, int64_t n, int64_t cin, const Bf16PackedWeights& w, const float* b,
                                bool relu, float* out);

}  // namespace layersnet::ad
