#include "autodiff/bf16_gemm.h"

#include "autodiff/check.h"
#include "autodiff/row_blocks.h"

#include <algorithm>
#include <bit>
#include <cstring>
#include <map>
#include <mutex>
#include <stdexcept>
#include <tuple>

#ifdef __AVX512BF16__
#include <immintrin.h>
#endif

namespace layersnet::ad {

bool bf16_available() {
#ifdef __AVX512BF16__
  return true;
#else
  return false;
#endif
}

const char* matmul_precision_name(MatmulPrecision p) {
  return p == MatmulPrecision::kBFloat16 ? "bf16" : "float32";
}

MatmulPrecision parse_matmul_precision(const std::string& text) {
  if (text == "float32" || text == "fp32" || text == "float") return MatmulPrecision::kFloat32;
  if (text == "bf16" || text == "bfloat16") return MatmulPrecision::kBFloat16;
  throw std::invalid_argument("matmul precision '" + text + "' is unknown; use float32 or bf16");
}

const char* bf16_kernel_name() { return bf16_available() ? "avx512-bf16" : "scalar reference"; }

uint16_t float_to_bf16(float f) {
  const uint32_t u = std::bit_cast<uint32_t>(f);
  if ((u & 0x7F800000u) == 0) return static_cast<uint16_t>((u >> 16) & 0x8000u);  // 0, denormal: signed 0
  if ((u & 0x7FFFFFFFu) > 0x7F800000u) return static_cast<uint16_t>((u >> 16) | 0x0040u);  // quiet NaN
  return static_cast<uint16_t>((u + 0x7FFFu + ((u >> 16) & 1u)) >> 16);  // nearest, ties to even
}

float bf16_to_float(uint16_t h) { return std::bit_cast<float>(static_cast<uint32_t>(h) << 16); }

// ---- packing and the cache ------------------------------------------------------------------

std::shared_ptr<const Bf16PackedWeights> bf16_pack_weights(const float* W, int64_t cout, int64_t cin) {
  LAYERSNET_CHECK(cout >= 1 && cin >= 1, "bf16_pack_weights: W is (" << cout << ", " << cin
                                             << "); a linear weight needs at least one row and one column");
  auto w = std::make_shared<Bf16PackedWeights>();
  w->cout = cout;
  w->cin = cin;
  w->pairs = (cin + 1) / 2;
  w->groups = (cout + 15) / 16;
  w->data.assign(static_cast<std::size_t>(w->groups * w->pairs * 32), uint16_t{0});
  for (int64_t r = 0; r < cout; ++r) {
    uint16_t* dst = w->data.data() + (r / 16) * w->pairs * 32 + 2 * (r % 16);
    for (int64_t c = 0; c < cin; ++c) dst[(c / 2) * 32 + (c % 2)] = float_to_bf16(W[r * cin + c]);
  }
  w->source.assign(W, W + cout * cin);
  return w;
}

namespace {

struct WeightCache {
  std::mutex mutex;
  std::map<std::tuple<const float*, int64_t, int64_t>, std::shared_ptr<const Bf16PackedWeights>> entries;
  int64_t packs = 0, hits = 0;
};

WeightCache& weight_cache() {
  static WeightCache cache;
  return cache;
}

}  // namespace

std::shared_ptr<const Bf16PackedWeights> bf16_cached_weights(const float* W, int64_t cout, int64_t cin) {
  WeightCache& c = weight_cache();
  const std::lock_guard<std::mutex> lock(c.mutex);
  const auto key = std::make_tuple(W, cout, cin);
  auto it = c.entries.find(key);
  if (it != c.entries.end() &&
      std::memcmp(it->second->source.data(), W, sizeof(float) * static_cast<std::size_t>(cout * cin)) == 0) {
    ++c.hits;
    return it->second;
  }
  auto packed = bf16_pack_weights(W, cout, cin);
  ++c.packs;
  if (it != c.entries.end()) {
    it->second = packed;
  } else {
    if (c.entries.size() >= kBf16CacheEntries) c.entries.clear();  // stale addresses of freed weights
    c.entries.emplace(key, packed);
  }
  return packed;
}

Bf16CacheStats bf16_weight_cache_stats() {
  WeightCache& c = weight_cache();
  const std::lock_guard<std::mutex> lock(c.mutex);
  return {c.packs, c.hits, static_cast<int64_t>(c.entries.size())};
}

void bf16_clear_weight_cache() {
  WeightCache& c = weight_cache();
  const std::lock_guard<std::mutex> lock(c.mutex);
  c.entries.clear();
  c.packs = c.hits = 0;
}

// ---- scalar reference ---------------------------------------------------------------------

namespace {

// Rows of x per parallel work item (both paths): small enough to balance two threads on
// N ~ 1000, and with Cin <= 300 the row block's bf16 copy (<= 29 KiB) stays in L1/L2.
constexpr int64_t kBlockRows = 48;

void check_shapes(const char* fn, int64_t n, int64_t cin, const Bf16PackedWeights& w) {
  LAYERSNET_CHECK(n >= 0 && cin == w.cin, fn << ": x is (" << n << ", " << cin << ") but the packed W is (" << w.cout
                                              << ", " << w.cin << "); W must be (Cout, Cin) with Cin = x's columns");
}

}  // namespace

// Kept unvectorized: Debian 12's GCC 12.2 vectorizes a float reduction that adds element
// 2p+1 before 2p into one accumulator into WRONG sums, even at plain -O2 (a 6-line loop
// summing exact integers returns 272 instead of 208; adding 2p first is fine; it looks like
// GCC PR 110381, fixed in later releases). Our order is VDPBF16PS's, so the loop keeps it
// and gives up vectorization; the reference path is not about speed. Caught by
// tests/autodiff/test_bf16.cpp.
#if defined(__GNUC__) && !defined(__clang__)
__attribute__((optimize("no-tree-vectorize")))
#endif
void bf16_linear_forward_scalar(const float* x, int64_t n, int64_t cin, const Bf16PackedWeights& w, const float* b,
                                bool relu, float* out) {
  check_shapes("bf16_linear_forward_scalar", n, cin, w);
  const int64_t cout = w.cout, pairs = w.pairs;
  const int64_t n_blocks = (n + kBlockRows - 1) / kBlockRows;
#pragma omp parallel for schedule(dynamic, 1) if (n_blocks > 1 && run_parallel(n, cin + cout))
  for (int64_t blk = 0; blk < n_blocks; ++blk) {
    static thread_local std::vector<float> xr;  // one row of x in bf16, padded to 2 * pairs
    xr.assign(static_cast<std::size_t>(2 * pairs), 0.0f);
    const int64_t r1 = std::min(n, (blk + 1) * kBlockRows);
    for (int64_t r = blk * kBlockRows; r < r1; ++r) {
      for (int64_t c = 0; c < cin; ++c) xr[c] = round_to_bf16(x[r * cin + c]);
      // 16 columns at a time, as the kernel.
      for (int64_t g = 0; g < w.groups; ++g) {
        const int64_t cols = std::min<int64_t>(16, cout - 16 * g);
        float acc[16] = {};
        for (int64_t j = 0; j < cols; ++j) acc[j] = b ? b[16 * g + j] : 0.0f;
        for (int64_t p = 0; p < pairs; ++p) {
          const float xo = xr[2 * p + 1], xe = xr[2 * p];
          const uint16_t* wp = w.data.data() + (g * pairs + p) * 32;
          // Products of bf16 values are exact in float: a fused multiply-add rounds the same.
          for (int j = 0; j < 16; ++j) {
            acc[j] += xo * bf16_to_float(wp[2 * j + 1]);
            acc[j] += xe * bf16_to_float(wp[2 * j]);
          }
        }
        for (int64_t j = 0; j < cols; ++j)  // NaN passes (as max(0, NaN) in the kernel)
          out[r * cout + 16 * g + j] = relu && acc[j] < 0.0f ? 0.0f : acc[j];
      }
    }
  }
}

// ---- AVX-512 BF16 kernel ------------------------------------------------------------------

#ifdef __AVX512BF16__
namespace {

// Micro-tile: kMr rows x up to 4 groups of 16 columns = 24 float accumulators in zmm
// registers (+ 4 weight vectors + 1 broadcast of 32). Each VDPBF16PS does 16 columns x 2
// channels of one row.
constexpr int kMr = 6;
constexpr int kMaxGroups = 4;

__mmask16 column_mask(int64_t remaining) {
  return remaining >= 16 ? __mmask16(0xFFFF) : static_cast<__mmask16>((1u << remaining) - 1u);
}

// xb[i * pairs + p] = [bf16(x_i,2p) | bf16(x_i,2p+1) << 16], zero past Cin. x: (m, cin).
void convert_rows(const float* x, int64_t m, int64_t cin, int64_t pairs, uint32_t* xb) {
  const int64_t padded = 2 * pairs;
  for (int64_t i = 0; i < m; ++i) {
    const float* xi = x + i * cin;
    uint16_t* dst = reinterpret_cast<uint16_t*>(xb + i * pairs);
    for (int64_t c = 0; c < cin; c += 32) {
      const int64_t rem = cin - c;
      const __m512 lo = _mm512_maskz_loadu_ps(column_mask(rem), xi + c);
      const __m512 hi = _mm512_maskz_loadu_ps(rem > 16 ? column_mask(rem - 16) : __mmask16(0), xi + c + 16);
      const __m512bh v = _mm512_cvtne2ps_pbh(hi, lo);  // elements 0..15 from lo
      const int64_t store = std::min<int64_t>(32, padded - c);
      const __mmask32 mask = store >= 32 ? __mmask32(0xFFFFFFFFu) : static_cast<__mmask32>((1u << store) - 1u);
      _mm512_mask_storeu_epi16(dst + c, mask, reinterpret_cast<const __m512i&>(v));
    }
  }
}

// out rows [0, MR) x column groups [g0, g0 + NV) of the block.
// xb: (MR, pairs) bf16 pairs; wg: packed W at group g0 (groups `gstride` apart); b: bias
// at column 16 g0 or null; out: first output entry (row 0, column 16 g0), rows ldo apart.
template <int MR, int NV>
void micro_tile(const uint32_t* xb, int64_t pairs, const uint16_t* wg, int64_t gstride, const float* b,
                int64_t cols_left, bool relu, float* out, int64_t ldo) {
  __m512 acc[MR][NV];
  for (int j = 0; j < NV; ++j) {
    const __m512 init = b ? _mm512_maskz_loadu_ps(column_mask(cols_left - 16 * j), b + 16 * j) : _mm512_setzero_ps();
    for (int i = 0; i < MR; ++i) acc[i][j] = init;
  }
  for (int64_t p = 0; p < pairs; ++p) {
    __m512bh w[NV];
    for (int j = 0; j < NV; ++j) {
      const __m512i v = _mm512_loadu_si512(wg + j * gstride + p * 32);
      w[j] = reinterpret_cast<const __m512bh&>(v);
    }
    for (int i = 0; i < MR; ++i) {
      const __m512i xv = _mm512_set1_epi32(static_cast<int>(xb[i * pairs + p]));
      const __m512bh a = reinterpret_cast<const __m512bh&>(xv);
      for (int j = 0; j < NV; ++j) acc[i][j] = _mm512_dpbf16_ps(acc[i][j], a, w[j]);
    }
  }
  const __m512 zero = _mm512_setzero_ps();
  for (int j = 0; j < NV; ++j) {
    const __mmask16 mask = column_mask(cols_left - 16 * j);
    for (int i = 0; i < MR; ++i)  // max(0, NaN) is NaN: a diverging rollout stays visible
      _mm512_mask_storeu_ps(out + i * ldo + 16 * j, mask, relu ? _mm512_max_ps(zero, acc[i][j]) : acc[i][j]);
  }
}

using MicroTile = void (*)(const uint32_t*, int64_t, const uint16_t*, int64_t, const float*, int64_t, bool, float*,
                           int64_t);

template <int MR>
MicroTile tile_for_groups(int nv) {
  switch (nv) {
    case 1: return micro_tile<MR, 1>;
    case 2: return micro_tile<MR, 2>;
    case 3: return micro_tile<MR, 3>;
    default: return micro_tile<MR, 4>;
  }
}

MicroTile tile_for(int mr, int nv) {
  switch (mr) {
    case 1: return tile_for_groups<1>(nv);
    case 2: return tile_for_groups<2>(nv);
    case 3: return tile_for_groups<3>(nv);
    case 4: return tile_for_groups<4>(nv);
    case 5: return tile_for_groups<5>(nv);
    default: return tile_for_groups<6>(nv);
  }
}

void forward_avx512(const float* x, int64_t n, int64_t cin, const Bf16PackedWeights& w, const float* b, bool relu,
                    float* out) {
  const int64_t cout = w.cout, pairs = w.pairs, groups = w.groups, gstride = pairs * 32;
  // Column panels of at most kMaxGroups groups, as even as possible (17 groups: 4 4 3 3 3),
  // so no panel wastes most of its registers.
  const int64_t panels = (groups + kMaxGroups - 1) / kMaxGroups;
  const int64_t n_blocks = (n + kBlockRows - 1) / kBlockRows;
#pragma omp parallel for schedule(dynamic, 1) if (n_blocks > 1 && run_parallel(n, cin + cout))
  for (int64_t blk = 0; blk < n_blocks; ++blk) {
    static thread_local std::vector<uint32_t> xb;  // grows once per thread
    if (xb.size() < static_cast<std::size_t>(kBlockRows * pairs)) xb.resize(static_cast<std::size_t>(kBlockRows * pairs));
    const int64_t r0 = blk * kBlockRows, m = std::min(kBlockRows, n - r0);
    convert_rows(x + r0 * cin, m, cin, pairs, xb.data());
    int64_t g0 = 0;
    for (int64_t panel = 0; panel < panels; ++panel) {
      const int nv = static_cast<int>(groups / panels + (panel < groups % panels ? 1 : 0));
      const int64_t col0 = 16 * g0;
      for (int64_t i0 = 0; i0 < m; i0 += kMr) {
        const int mr = static_cast<int>(std::min<int64_t>(kMr, m - i0));
        tile_for(mr, nv)(xb.data() + i0 * pairs, pairs, w.data.data() + g0 * gstride, gstride, b ? b + col0 : nullptr,
                         cout - col0, relu, out + (r0 + i0) * cout + col0, cout);
      }
      g0 += nv;
    }
  }
}

}  // namespace
#endif

void bf16_linear_forward(const float* x, int64_t n, int64_t cin, const Bf16PackedWeights& w, const float* b,
                         bool relu, float* out) {
  check_shapes("bf16_linear_forward", n, cin, w);
  if (n == 0) return;
#ifdef __AVX512BF16__
  forward_avx512(x, n, cin, w, b, relu, out);
#else
  bf16_linear_forward_scalar(x, n, cin, w, b, relu, out);
#endif
}

}  // namespace layersnet::ad
