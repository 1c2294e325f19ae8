#include "autodiff/bf16_gemm.h"

#include "autodiff/check.h"
#include "autodiff/row_blocks.h"

#include <algorithm>
#include <bit>
#include <chrono>
#include <cstdlib>
#include <cstring>
#include <map>
#include <mutex>
#include <stdexcept>
#include <string>
#include <tuple>

#if defined(__x86_64__) && defined(__GNUC__)
#include <cpuid.h>
#endif
#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__)
#define LAYERSNET_AMX_KERNEL 1
#include <sys/syscall.h>
#include <unistd.h>
#endif
#if defined(__AVX512BF16__) || defined(LAYERSNET_AMX_KERNEL)
#include <immintrin.h>
#endif

namespace layersnet::ad {

namespace {

#ifdef LAYERSNET_AMX_KERNEL
// The CPU has AMX-TILE, AMX-BF16, AVX-512 F/BW/BF16, the OS saves their state, and Linux
// lets this process use the tile data (it must be asked for once per process).
bool detect_amx() {
  unsigned a = 0, b = 0, c = 0, d = 0;
  if (!__get_cpuid_count(7, 0, &a, &b, &c, &d)) return false;
  const bool amx = ((d >> 24) & 1u) && ((d >> 22) & 1u);        // AMX-TILE, AMX-BF16
  const bool avx512 = ((b >> 16) & 1u) && ((b >> 30) & 1u);     // AVX512F, AVX512BW
  if (!amx || !avx512 || a < 1) return false;
  if (!__get_cpuid_count(7, 1, &a, &b, &c, &d) || !((a >> 5) & 1u)) return false;  // AVX512-BF16
  if (!__get_cpuid(1, &a, &b, &c, &d) || !((c >> 27) & 1u)) return false;           // OSXSAVE
  unsigned lo = 0, hi = 0;
  __asm__ volatile("xgetbv" : "=a"(lo), "=d"(hi) : "c"(0));
  const unsigned wanted = (1u << 1) | (1u << 2) | (7u << 5) | (3u << 17);  // SSE, AVX, AVX-512, tiles
  if ((lo & wanted) != wanted) return false;
  constexpr long kArchReqXcompPerm = 0x1023, kXfeatureXtiledata = 18;
  return syscall(SYS_arch_prctl, kArchReqXcompPerm, kXfeatureXtiledata) == 0;
}
#endif

bool amx_usable() {
#ifdef LAYERSNET_AMX_KERNEL
  static const bool usable = detect_amx();
  return usable;
#else
  return false;
#endif
}

Bf16Kernel choose_kernel() {
  const char* env = std::getenv("LAYERSNET_BF16_KERNEL");
  if (env && *env) {
    const std::string name = env;
    Bf16Kernel k;
    if (name == "amx-bf16" || name == "amx") k = Bf16Kernel::kAmx;
    else if (name == "avx512-bf16" || name == "avx512") k = Bf16Kernel::kAvx512;
    else if (name == "scalar") k = Bf16Kernel::kScalar;
    else
      throw std::runtime_error("LAYERSNET_BF16_KERNEL='" + name +
                               "' is unknown; use amx-bf16, avx512-bf16 or scalar, or unset it for the fastest");
    if (!bf16_kernel_available(k))
      throw std::runtime_error("LAYERSNET_BF16_KERNEL='" + name + "' cannot run on this CPU or build; unset it (the " +
                               "fastest available is used) or name another");
    return k;
  }
  if (bf16_kernel_available(Bf16Kernel::kAmx)) return Bf16Kernel::kAmx;
  if (bf16_kernel_available(Bf16Kernel::kAvx512)) return Bf16Kernel::kAvx512;
  return Bf16Kernel::kScalar;
}

}  // namespace

bool bf16_kernel_available(Bf16Kernel kernel) {
  switch (kernel) {
    case Bf16Kernel::kAmx: return amx_usable();
    case Bf16Kernel::kAvx512:
#ifdef __AVX512BF16__
      return true;
#else
      return false;
#endif
    case Bf16Kernel::kScalar: return true;
  }
  return false;
}

Bf16Kernel bf16_kernel() {
  static const Bf16Kernel kernel = choose_kernel();
  return kernel;
}

const char* bf16_kernel_name(Bf16Kernel kernel) {
  switch (kernel) {
    case Bf16Kernel::kAmx: return "amx-bf16";
    case Bf16Kernel::kAvx512: return "avx512-bf16";
    case Bf16Kernel::kScalar: return "scalar reference";
  }
  return "?";
}

const char* bf16_kernel_name() { return bf16_kernel_name(bf16_kernel()); }

bool bf16_available() { return bf16_kernel() != Bf16Kernel::kScalar; }

namespace {

bool amd_cpu() {
#if defined(__x86_64__) && defined(__GNUC__)
  unsigned a = 0, b = 0, c = 0, d = 0;
  if (!__get_cpuid(0, &a, &b, &c, &d)) return false;
  char vendor[13] = {};
  std::memcpy(vendor, &b, 4);
  std::memcpy(vendor + 4, &d, 4);
  std::memcpy(vendor + 8, &c, 4);
  return std::strcmp(vendor, "AuthenticAMD") == 0;
#else
  return false;
#endif
}

}  // namespace

bool bf16_outruns_float32() {
  switch (bf16_kernel()) {
    case Bf16Kernel::kAmx: return true;
    case Bf16Kernel::kAvx512: return amd_cpu();
    case Bf16Kernel::kScalar: return false;
  }
  return false;
}

#ifdef __AVX512BF16__
namespace {

// Seconds for `iters` rounds of 24 independent accumulations acc = step(acc, operand), no loads.
template <class Operand, class Step>
double time_accumulations(long iters, Operand operand, Step step) {
  __m512 acc[24];
  for (__m512& a : acc) a = _mm512_setzero_ps();
  const auto start = std::chrono::steady_clock::now();
  for (long i = 0; i < iters; ++i) {
#pragma GCC unroll 24
    for (int j = 0; j < 24; ++j) acc[j] = step(acc[j], operand);
    __asm__ volatile("" : "+v"(operand));  // a new operand each round: no step is hoisted or merged
  }
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  __m512 sum = acc[0];
  for (int j = 1; j < 24; ++j) sum = _mm512_add_ps(sum, acc[j]);
  alignas(64) float lanes[16];
  _mm512_store_ps(lanes, sum);
  volatile float kept = lanes[0];  // the accumulations are used
  (void)kept;
  return seconds;
}

}  // namespace
#endif

DotRates measure_dot_rates(int rounds) {
  DotRates r;
#ifdef __AVX512BF16__
  const __m512i ones = _mm512_set1_epi32(0x3F803F80);  // bf16 pairs (1, 1)
  const __m512bh w = reinterpret_cast<const __m512bh&>(ones);
  const __m512 x = _mm512_set1_ps(1.0f);
  constexpr long kIters = 200000;
  for (int k = 0; k < rounds; ++k) {
    const double t_bf16 = time_accumulations(kIters, w, [](__m512 a, __m512bh v) { return _mm512_dpbf16_ps(a, v, v); });
    const double t_fma = time_accumulations(kIters, x, [](__m512 a, __m512 v) { return _mm512_fmadd_ps(v, v, a); });
    r.bf16_gmacs = std::max(r.bf16_gmacs, 24.0 * 32 * kIters / t_bf16 * 1e-9);
    r.fma_gmacs = std::max(r.fma_gmacs, 24.0 * 16 * kIters / t_fma * 1e-9);
  }
#else
  (void)rounds;
#endif
  return r;
}

const char* matmul_precision_name(MatmulPrecision p) {
  return p == MatmulPrecision::kBFloat16 ? "bf16" : "float32";
}

MatmulPrecision parse_matmul_precision(const std::string& text) {
  if (text == "float32" || text == "fp32" || text == "float") return MatmulPrecision::kFloat32;
  if (text == "bf16" || text == "bfloat16") return MatmulPrecision::kBFloat16;
  throw std::invalid_argument("matmul precision '" + text + "' is unknown; use float32 or bf16");
}

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
  if (bf16_kernel_available(Bf16Kernel::kAmx)) {
    w->tile_pairs = (w->pairs + 15) / 16 * 16;
    w->tiles.assign(static_cast<std::size_t>(w->groups * w->tile_pairs * 32), uint16_t{0});
    for (int64_t g = 0; g < w->groups; ++g)
      std::copy_n(w->data.data() + g * w->pairs * 32, w->pairs * 32, w->tiles.data() + g * w->tile_pairs * 32);
  }
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


// ---- AMX kernel ---------------------------------------------------------------------------

#ifdef LAYERSNET_AMX_KERNEL
namespace {

#define LAYERSNET_AMX_TARGET __attribute__((target("amx-tile,amx-bf16,avx512f,avx512bw,avx512bf16")))

// Tiles: 0-3 outputs (16 rows x 16 floats), 4-5 rows of x (16 rows x 16 pairs), 6-7 weights
// (16 pairs x 16 columns, VNNI). A block of 32 rows x 32 columns takes 4 products per 32 channels.
constexpr int64_t kAmxRows = 32;

struct alignas(64) TileConfig {
  uint8_t palette = 1, start_row = 0;
  uint8_t reserved[14] = {};
  uint16_t colsb[16] = {};
  uint8_t rows[16] = {};
};

LAYERSNET_AMX_TARGET void load_tile_config() {
  TileConfig cfg;
  for (int t = 0; t < 8; ++t) {
    cfg.colsb[t] = 64;
    cfg.rows[t] = 16;
  }
  __asm__ volatile("" ::: "memory");
  _tile_loadconfig(&cfg);
}

// Rows [0, m) of x (m <= 32) as bf16 pairs, xb: (32, tile_pairs) zero past Cin and past m.
LAYERSNET_AMX_TARGET void convert_block(const float* x, int64_t m, int64_t cin, int64_t tile_pairs, uint32_t* xb) {
  std::memset(xb, 0, sizeof(uint32_t) * static_cast<std::size_t>(kAmxRows * tile_pairs));
  for (int64_t i = 0; i < m; ++i) {
    const float* xi = x + i * cin;
    uint16_t* dst = reinterpret_cast<uint16_t*>(xb + i * tile_pairs);
    for (int64_t c = 0; c < cin; c += 32) {
      const int64_t rem = cin - c;
      const __mmask16 lo_mask = rem >= 16 ? __mmask16(0xFFFF) : static_cast<__mmask16>((1u << rem) - 1u);
      const __mmask16 hi_mask =
          rem >= 32 ? __mmask16(0xFFFF) : rem > 16 ? static_cast<__mmask16>((1u << (rem - 16)) - 1u) : __mmask16(0);
      const __m512 lo = _mm512_maskz_loadu_ps(lo_mask, xi + c);
      const __m512 hi = _mm512_maskz_loadu_ps(hi_mask, xi + c + 16);
      const __m512bh v = _mm512_cvtne2ps_pbh(hi, lo);  // the same rounding as float_to_bf16
      _mm512_storeu_si512(dst + c, reinterpret_cast<const __m512i&>(v));  // within the padded row
    }
  }
  __asm__ volatile("" ::: "memory");  // the tile loads below read xb
}

// Output rows [r0, r0 + 16 * (1 + TWO_ROWS)) x column groups g, g + TWO_COLS of the block.
// bias_tiles: per group, 16 rows of its 16 biases (the accumulators start there, as in the
// other kernels). The products are stored to `scratch` (32 x 32 floats) and copied out.
template <bool TWO_ROWS, bool TWO_COLS>
LAYERSNET_AMX_TARGET void amx_block(const uint32_t* xb, int64_t tile_pairs, const uint16_t* wg, const float* bias_g,
                                    float* scratch) {
  const long x_stride = static_cast<long>(tile_pairs * 4);
  const uint16_t* wg1 = wg + tile_pairs * 32;
  _tile_loadd(0, bias_g, 64);
  if constexpr (TWO_ROWS) _tile_loadd(1, bias_g, 64);
  if constexpr (TWO_COLS) {
    _tile_loadd(2, bias_g + 256, 64);
    if constexpr (TWO_ROWS) _tile_loadd(3, bias_g + 256, 64);
  }
  for (int64_t kb = 0; kb < tile_pairs; kb += 16) {
    _tile_loadd(4, xb + kb, x_stride);
    if constexpr (TWO_ROWS) _tile_loadd(5, xb + 16 * tile_pairs + kb, x_stride);
    _tile_loadd(6, wg + kb * 32, 64);
    _tile_dpbf16ps(0, 4, 6);
    if constexpr (TWO_ROWS) _tile_dpbf16ps(1, 5, 6);
    if constexpr (TWO_COLS) {
      _tile_loadd(7, wg1 + kb * 32, 64);
      _tile_dpbf16ps(2, 4, 7);
      if constexpr (TWO_ROWS) _tile_dpbf16ps(3, 5, 7);
    }
  }
  _tile_stored(0, scratch, 128);
  if constexpr (TWO_ROWS) _tile_stored(1, scratch + 16 * 32, 128);
  if constexpr (TWO_COLS) {
    _tile_stored(2, scratch + 16, 128);
    if constexpr (TWO_ROWS) _tile_stored(3, scratch + 16 * 32 + 16, 128);
  }
}

LAYERSNET_AMX_TARGET void forward_amx(const float* x, int64_t n, int64_t cin, const Bf16PackedWeights& w,
                                      const float* b, bool relu, float* out) {
  const int64_t cout = w.cout, tp = w.tile_pairs, groups = w.groups;
  LAYERSNET_CHECK(tp > 0 && static_cast<int64_t>(w.tiles.size()) == groups * tp * 32,
                  "bf16 amx kernel: the weights were packed without their tile layout (packed before AMX was usable?)");
  const int64_t n_blocks = (n + kAmxRows - 1) / kAmxRows;
#pragma omp parallel if (n_blocks > 1 && run_parallel(n, cin + cout))
  {
    static thread_local std::vector<uint32_t> xb;     // (32, tile_pairs)
    static thread_local std::vector<float> bias_rows;  // (groups, 16, 16)
    alignas(64) float scratch[kAmxRows * 32];
    if (xb.size() < static_cast<std::size_t>(kAmxRows * tp)) xb.resize(static_cast<std::size_t>(kAmxRows * tp));
    bias_rows.assign(static_cast<std::size_t>(groups * 256), 0.0f);
    if (b)
      for (int64_t g = 0; g < groups; ++g)
        for (int64_t j = 0; j < 16 && 16 * g + j < cout; ++j)
          for (int64_t i = 0; i < 16; ++i) bias_rows[static_cast<std::size_t>(g * 256 + i * 16 + j)] = b[16 * g + j];
    load_tile_config();
#pragma omp for schedule(dynamic, 1)
    for (int64_t blk = 0; blk < n_blocks; ++blk) {
      const int64_t r0 = blk * kAmxRows, m = std::min(kAmxRows, n - r0);
      convert_block(x + r0 * cin, m, cin, tp, xb.data());
      const bool two_rows = m > 16;
      for (int64_t g = 0; g < groups; g += 2) {
        const bool two_cols = g + 1 < groups;
        const uint16_t* wg = w.tiles.data() + g * tp * 32;
        const float* bias_g = bias_rows.data() + g * 256;
        if (two_rows) {
          if (two_cols) amx_block<true, true>(xb.data(), tp, wg, bias_g, scratch);
          else amx_block<true, false>(xb.data(), tp, wg, bias_g, scratch);
        } else {
          if (two_cols) amx_block<false, true>(xb.data(), tp, wg, bias_g, scratch);
          else amx_block<false, false>(xb.data(), tp, wg, bias_g, scratch);
        }
        const int64_t col0 = 16 * g, cols = std::min<int64_t>(two_cols ? 32 : 16, cout - col0);
        const __mmask16 m0 = cols >= 16 ? __mmask16(0xFFFF) : static_cast<__mmask16>((1u << cols) - 1u);
        const __mmask16 m1 = cols >= 32 ? __mmask16(0xFFFF)
                             : cols > 16 ? static_cast<__mmask16>((1u << (cols - 16)) - 1u)
                                         : __mmask16(0);
        const __m512 zero = _mm512_setzero_ps();
        for (int64_t i = 0; i < m; ++i) {
          __m512 v0 = _mm512_load_ps(scratch + i * 32), v1 = _mm512_load_ps(scratch + i * 32 + 16);
          if (relu) {  // max(0, NaN) is NaN: a diverging rollout stays visible
            v0 = _mm512_max_ps(zero, v0);
            v1 = _mm512_max_ps(zero, v1);
          }
          _mm512_mask_storeu_ps(out + (r0 + i) * cout + col0, m0, v0);
          if (m1) _mm512_mask_storeu_ps(out + (r0 + i) * cout + col0 + 16, m1, v1);
        }
      }
    }
    _tile_release();
  }
}

#undef LAYERSNET_AMX_TARGET

}  // namespace
#endif

void bf16_linear_forward(const float* x, int64_t n, int64_t cin, const Bf16PackedWeights& w, const float* b,
                         bool relu, float* out, Bf16Kernel kernel) {
  check_shapes("bf16_linear_forward", n, cin, w);
  LAYERSNET_CHECK(bf16_kernel_available(kernel),
                  "bf16_linear_forward: the " << bf16_kernel_name(kernel) << " kernel cannot run on this CPU or build");
  if (n == 0) return;
  switch (kernel) {
    case Bf16Kernel::kAmx:
#ifdef LAYERSNET_AMX_KERNEL
      forward_amx(x, n, cin, w, b, relu, out);
      return;
#else
      break;
#endif
    case Bf16Kernel::kAvx512:
#ifdef __AVX512BF16__
      forward_avx512(x, n, cin, w, b, relu, out);
      return;
#else
      break;
#endif
    case Bf16Kernel::kScalar: break;
  }
  bf16_linear_forward_scalar(x, n, cin, w, b, relu, out);
}

}  // namespace layersnet::ad
