// bfloat16 linear products (autodiff/bf16_gemm.h) and their hook in linear / linear_relu.
//
// Bounds used below (u_f = 2^-24 float, u = 2^-8 bfloat16 unit roundoff; S = |b| + Σ_k |x̂_k ŵ_k|):
// - against a double reference of the bf16-ROUNDED inputs x̂, ŵ, only the float accumulation
//   differs: Cin + 1 rounded additions, so |err| <= (Cin + 1) u_f S (first order); we allow
//   (Cin + 2) u_f S.
// - against the float product of the unrounded inputs: x̂ = x(1 + d1), ŵ = w(1 + d2) with
//   |d| <= u, so |x̂ŵ − xw| <= (2u + u²)|xw|; plus both accumulations: (2u + u²) S + 2 (Cin + 2) u_f S.
#include "autodiff/bf16_gemm.h"
#include "autodiff/ops_dense.h"

#include <gtest/gtest.h>
#include <omp.h>

#include <array>
#include <bit>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <iostream>
#include <limits>
#include <random>
#include <string>
#include <vector>

#ifdef __AVX512BF16__
#include <immintrin.h>
#endif

namespace layersnet::ad {
namespace {

constexpr double kUf = 1.0 / (1 << 24);
constexpr double kU = 1.0 / (1 << 8);

std::vector<float> random_floats(int64_t n, unsigned seed, float scale = 1.0f) {
  std::mt19937 rng(seed);
  std::normal_distribution<float> g(0.0f, scale);
  std::vector<float> v(static_cast<std::size_t>(n));
  for (float& x : v) x = g(rng);
  return v;
}

struct Shape {
  int64_t n, cin, cout;
};

// Every kernel this build can run on this CPU (the scalar reference always).
std::vector<Bf16Kernel> available_kernels() {
  std::vector<Bf16Kernel> ks;
  for (Bf16Kernel k : {Bf16Kernel::kScalar, Bf16Kernel::kAvx512, Bf16Kernel::kAmx})
    if (bf16_kernel_available(k)) ks.push_back(k);
  return ks;
}

// Odd and degenerate shapes: one row, no rows, odd Cin, Cout not a multiple of 16, row
// counts not multiples of the 6-row tile or the 48-row block, and sizes that run in parallel.
// (and of the AMX kernel's 16-row tiles and 32-row blocks, and its 32-channel blocks).
const std::vector<Shape> kShapes = {{1, 16, 16},    {0, 8, 20},     {7, 33, 17},    {13, 1, 5},
                                    {5, 2, 64},     {37, 31, 47},   {50, 128, 128}, {97, 268, 268},
                                    {1000, 40, 70}, {2003, 129, 33}, {16, 32, 16},  {33, 64, 48},
                                    {31, 65, 33}};

// Double reference of out = x̂ ŵᵀ + b, and S = |b| + Σ|x̂ ŵ| per entry. x: (N, Cin); W: (Cout, Cin).
void reference(const std::vector<float>& x, const std::vector<float>& W, const float* b, const Shape& s, bool round,
               std::vector<double>& out, std::vector<double>& mag) {
  out.assign(static_cast<std::size_t>(s.n * s.cout), 0.0);
  mag = out;
  for (int64_t i = 0; i < s.n; ++i)
    for (int64_t j = 0; j < s.cout; ++j) {
      double acc = b ? b[j] : 0.0, m = b ? std::abs(b[j]) : 0.0;
      for (int64_t k = 0; k < s.cin; ++k) {
        const float xv = x[i * s.cin + k], wv = W[j * s.cin + k];
        const double p = round ? double(round_to_bf16(xv)) * round_to_bf16(wv) : double(xv) * wv;
        acc += p;
        m += std::abs(p);
      }
      out[i * s.cout + j] = acc;
      mag[i * s.cout + j] = m;
    }
}

TEST(Bf16, RoundsToNearestEven) {
  EXPECT_EQ(float_to_bf16(1.0f), 0x3F80);
  EXPECT_EQ(float_to_bf16(std::bit_cast<float>(0x3F808000u)), 0x3F80);  // tie, even below
  EXPECT_EQ(float_to_bf16(std::bit_cast<float>(0x3F818000u)), 0x3F82);  // tie, even above
  EXPECT_EQ(float_to_bf16(std::bit_cast<float>(0x3F808001u)), 0x3F81);  // just above the tie
  EXPECT_EQ(float_to_bf16(std::bit_cast<float>(0x3F807FFFu)), 0x3F80);  // just below
  EXPECT_EQ(float_to_bf16(-2.5f), 0xC020);
  EXPECT_EQ(float_to_bf16(std::numeric_limits<float>::denorm_min()), 0x0000);  // denormals flush
  EXPECT_EQ(float_to_bf16(-std::numeric_limits<float>::denorm_min()), 0x8000);
  EXPECT_EQ(float_to_bf16(std::numeric_limits<float>::infinity()), 0x7F80);
  EXPECT_EQ(float_to_bf16(std::numeric_limits<float>::max()), 0x7F80);  // beyond bf16's max: inf
  EXPECT_TRUE(std::isnan(round_to_bf16(std::numeric_limits<float>::quiet_NaN())));
  EXPECT_TRUE(std::isnan(round_to_bf16(std::bit_cast<float>(0x7F800001u))));  // signalling NaN stays NaN
  std::cout << "bf16 kernel: " << bf16_kernel_name() << "\n";
}

#ifdef __AVX512BF16__
// Our scalar conversion is bit-identical to the instruction the kernel uses.
TEST(Bf16, ScalarConversionMatchesTheInstruction) {
  std::mt19937 rng(5);
  std::vector<uint32_t> bits(1 << 16);
  for (auto& u : bits) u = rng();
  for (uint32_t k = 0; k < 256; ++k) bits[k] = 0x3F800000u + (k << 15);  // every other one a tie
  for (uint32_t k = 0; k < 256; ++k) bits[256 + k] = (k << 7) | (k & 1u ? 0x80000000u : 0u);  // denormals
  for (std::size_t i = 0; i < bits.size(); i += 32) {
    float f[32];
    for (int j = 0; j < 32; ++j) f[j] = std::bit_cast<float>(bits[i + j]);
    const __m512bh v = _mm512_cvtne2ps_pbh(_mm512_loadu_ps(f + 16), _mm512_loadu_ps(f));
    uint16_t h[32];
    std::memcpy(h, &v, sizeof h);
    for (int j = 0; j < 32; ++j) {
      if (std::isnan(f[j])) EXPECT_TRUE(std::isnan(bf16_to_float(h[j])));
      else ASSERT_EQ(h[j], float_to_bf16(f[j])) << std::hex << bits[i + j];
    }
  }
}
#endif

// Each kernel against the double reference of the rounded inputs. The AVX-512 kernel adds in
// the order of Intel's VDPBF16PS pseudo-code, as the scalar path does: the two agree bit for bit
// (observed on AMD Zen 4 and Intel Xeon). The AMX tile unit sums the same products in its own
// order, so it only has to keep the float accumulation bound.
TEST(Bf16, KernelsMatchTheDoubleReferenceOfRoundedInputs) {
  for (Bf16Kernel k : available_kernels()) {
    double worst_vs_scalar = 0;
    for (const Shape& s : kShapes) {
      const auto x = random_floats(s.n * s.cin, 11), W = random_floats(s.cout * s.cin, 12, 0.2f),
                 b = random_floats(s.cout, 13);
      const auto packed = bf16_pack_weights(W.data(), s.cout, s.cin);
      std::vector<float> out(static_cast<std::size_t>(s.n * s.cout), -7.0f), scalar = out;
      bf16_linear_forward(x.data(), s.n, s.cin, *packed, b.data(), false, out.data(), k);
      bf16_linear_forward_scalar(x.data(), s.n, s.cin, *packed, b.data(), false, scalar.data());
      std::vector<double> ref, mag;
      reference(x, W, b.data(), s, true, ref, mag);
      for (std::size_t e = 0; e < ref.size(); ++e) {
        const double tol = (s.cin + 2) * kUf * mag[e];
        ASSERT_LE(std::abs(out[e] - ref[e]), tol)
            << bf16_kernel_name(k) << ", shape " << s.n << "x" << s.cin << ">" << s.cout << " entry " << e;
        ASSERT_LE(std::abs(scalar[e] - ref[e]), tol) << "scalar, shape " << s.n << "x" << s.cin << ">" << s.cout;
        worst_vs_scalar = std::max(worst_vs_scalar, std::abs(double(out[e]) - scalar[e]) / mag[e]);
      }
    }
    std::cout << bf16_kernel_name(k) << " vs scalar path: max |diff| / S = " << worst_vs_scalar << "\n";
    if (k != Bf16Kernel::kAmx) {
      EXPECT_EQ(worst_vs_scalar, 0.0) << bf16_kernel_name(k);
    }
  }
}

TEST(Bf16, WithinTheBf16BoundOfTheFloatProduct) {
  for (Bf16Kernel k : available_kernels())
  for (const Shape& s : kShapes) {
    if (s.n == 0) continue;
    const auto x = random_floats(s.n * s.cin, 21), W = random_floats(s.cout * s.cin, 22, 0.2f),
               b = random_floats(s.cout, 23);
    std::vector<float> out(static_cast<std::size_t>(s.n * s.cout));
    bf16_linear_forward(x.data(), s.n, s.cin, *bf16_pack_weights(W.data(), s.cout, s.cin), b.data(), false, out.data(),
                        k);
    std::vector<double> ref, mag;
    reference(x, W, b.data(), s, false, ref, mag);
    double worst = 0;
    for (std::size_t e = 0; e < ref.size(); ++e) {
      const double err = std::abs(out[e] - ref[e]) / mag[e];
      ASSERT_LE(err, 2 * kU + kU * kU + 2 * (s.cin + 2) * kUf)
          << bf16_kernel_name(k) << ", shape " << s.n << "x" << s.cin << ">" << s.cout;
      worst = std::max(worst, err);
    }
    // The inputs really were rounded (not a float product in disguise): some entry is off by
    // far more than float accumulation could explain.
    if (s.n * s.cout >= 16) {
      EXPECT_GT(worst, kU / 16) << bf16_kernel_name(k) << ", " << s.n << "x" << s.cin << ">" << s.cout;  // float alone: < (Cin + 2) u_f ~ kU / 200
    }
  }
}

TEST(Bf16, ReluIsTheMaxOfTheSameProducts) {
  for (Bf16Kernel k : available_kernels())
  for (const Shape& s : kShapes) {
    const auto x = random_floats(s.n * s.cin, 31), W = random_floats(s.cout * s.cin, 32, 0.2f);
    const auto packed = bf16_pack_weights(W.data(), s.cout, s.cin);
    std::vector<float> y(static_cast<std::size_t>(s.n * s.cout)), r = y, rs = y;
    bf16_linear_forward(x.data(), s.n, s.cin, *packed, nullptr, false, y.data(), k);  // no bias too
    bf16_linear_forward(x.data(), s.n, s.cin, *packed, nullptr, true, r.data(), k);
    bf16_linear_forward_scalar(x.data(), s.n, s.cin, *packed, nullptr, true, rs.data());
    int negatives = 0;
    for (std::size_t e = 0; e < y.size(); ++e) {
      ASSERT_EQ(r[e], std::max(0.0f, y[e])) << bf16_kernel_name(k);
      if (k != Bf16Kernel::kAmx || std::abs(y[e]) > 1e-3f) {  // AMX may round a near-zero sum to the other side
        ASSERT_EQ(rs[e] == 0.0f, r[e] == 0.0f) << bf16_kernel_name(k);
      }
      negatives += y[e] < 0;
    }
    if (y.size() >= 64) {
      EXPECT_GT(negatives, 0);
    }
  }
}

TEST(Bf16, SameBitsForAnyThreadCount) {
  const Shape s{5000, 72, 40};
  const auto x = random_floats(s.n * s.cin, 41), W = random_floats(s.cout * s.cin, 42), b = random_floats(s.cout, 43);
  const auto packed = bf16_pack_weights(W.data(), s.cout, s.cin);
  for (Bf16Kernel k : available_kernels()) {
    std::vector<float> one(static_cast<std::size_t>(s.n * s.cout)), two = one;
    const int was = omp_get_max_threads();
    omp_set_num_threads(1);
    bf16_linear_forward(x.data(), s.n, s.cin, *packed, b.data(), true, one.data(), k);
    omp_set_num_threads(2);
    bf16_linear_forward(x.data(), s.n, s.cin, *packed, b.data(), true, two.data(), k);
    omp_set_num_threads(was);
    EXPECT_EQ(std::memcmp(one.data(), two.data(), sizeof(float) * one.size()), 0) << bf16_kernel_name(k);
  }
}

// The fastest kernel runs unless LAYERSNET_BF16_KERNEL names another (not set under ctest).
TEST(Bf16, TheFastestAvailableKernelRuns) {
  if (std::getenv("LAYERSNET_BF16_KERNEL")) GTEST_SKIP() << "LAYERSNET_BF16_KERNEL is set";
  const Bf16Kernel expected = bf16_kernel_available(Bf16Kernel::kAmx)      ? Bf16Kernel::kAmx
                              : bf16_kernel_available(Bf16Kernel::kAvx512) ? Bf16Kernel::kAvx512
                                                                           : Bf16Kernel::kScalar;
  EXPECT_EQ(bf16_kernel(), expected);
  EXPECT_EQ(bf16_available(), expected != Bf16Kernel::kScalar);
  EXPECT_STREQ(bf16_kernel_name(), bf16_kernel_name(expected));
}

// The CPU's vendor as Linux reports it ("" where /proc/cpuinfo has no vendor_id line).
std::string cpuinfo_vendor() {
  std::ifstream in("/proc/cpuinfo");
  for (std::string line; std::getline(in, line);)
    if (line.rfind("vendor_id", 0) == 0) return line.substr(line.find(':') + 2);
  return "";
}

// bf16 is preferred with AMX tiles, and with the AVX-512 BF16 kernel only on an AMD core; never
// with the scalar reference. The peak-rate probe runs where the build has AVX-512 BF16.
TEST(Bf16, PreferredOverFloat32OnlyWhereItOutrunsIt) {
  switch (bf16_kernel()) {
    case Bf16Kernel::kAmx: EXPECT_TRUE(bf16_outruns_float32()); break;
    case Bf16Kernel::kAvx512: EXPECT_EQ(bf16_outruns_float32(), cpuinfo_vendor() == "AuthenticAMD"); break;
    case Bf16Kernel::kScalar: EXPECT_FALSE(bf16_outruns_float32()); break;
  }
  const DotRates r = measure_dot_rates(1);
  if (bf16_kernel_available(Bf16Kernel::kAvx512)) {
    EXPECT_TRUE(std::isfinite(r.bf16_gmacs) && r.bf16_gmacs > 0) << r.bf16_gmacs;
    EXPECT_TRUE(std::isfinite(r.fma_gmacs) && r.fma_gmacs > 0) << r.fma_gmacs;
  } else {
    EXPECT_EQ(r.bf16_gmacs, 0.0);
    EXPECT_EQ(r.fma_gmacs, 0.0);
  }
}

// ---- the hook in linear / linear_relu ---------------------------------------------------------

TEST(Bf16Linear, UsesTheKernelWithoutRecordingAndRepacksChangedWeights) {
  const Shape s{300, 40, 24};
  auto x = random_floats(s.n * s.cin, 51), W = random_floats(s.cout * s.cin, 52, 0.3f), b = random_floats(s.cout, 53);
  bf16_clear_weight_cache();
  Tape<float> tape;
  NoRecord<float> off(tape);
  MatmulPrecisionScope<float> bf16(tape, MatmulPrecision::kBFloat16);
  const Var<float> xv = tape.constant(x.data(), s.n, s.cin), bv = tape.constant(b.data(), 1, s.cout);
  const Var<float> Wv{W.data(), nullptr, s.cout, s.cin};  // a parameter-like buffer that we change in place
  std::vector<float> direct(static_cast<std::size_t>(s.n * s.cout));
  auto expect_direct = [&](const Var<float>& y, bool relu) {
    bf16_linear_forward(x.data(), s.n, s.cin, *bf16_pack_weights(W.data(), s.cout, s.cin), b.data(), relu, direct.data());
    ASSERT_EQ(std::memcmp(y.value, direct.data(), sizeof(float) * direct.size()), 0);
  };
  expect_direct(linear(tape, xv, Wv, bv), false);
  EXPECT_EQ(bf16_weight_cache_stats().packs, 1);
  expect_direct(linear_relu(tape, xv, Wv, bv), true);
  expect_direct(linear(tape, xv, Wv, bv), false);
  EXPECT_EQ(bf16_weight_cache_stats().packs, 1);  // the same weights: no repacking
  EXPECT_EQ(bf16_weight_cache_stats().hits, 2);
  W[7] += 0.5f;  // e.g. an optimizer step or a checkpoint load into the same buffer
  expect_direct(linear(tape, xv, Wv, bv), false);
  EXPECT_EQ(bf16_weight_cache_stats().packs, 2);
  EXPECT_EQ(bf16_weight_cache_stats().entries, 1);
  // The float path is back once the scope ends... (checked in the next test); here the
  // result differs from float, as it must.
  std::vector<float> fl(direct.size());
  {
    MatmulPrecisionScope<float> f32(tape, MatmulPrecision::kFloat32);
    const Var<float> y = linear(tape, xv, Wv, bv);
    std::memcpy(fl.data(), y.value, sizeof(float) * fl.size());
  }
  EXPECT_NE(std::memcmp(fl.data(), direct.data(), sizeof(float) * fl.size()), 0);
}

TEST(Bf16Linear, MlpRunsItsWideLayersOnTheKernel) {
  // 40 -> 300 -> 300 -> 3 over 1,000 rows: several cache blocks and chunks; the last layer is
  // narrow and stays float, as in linear.
  const int64_t n = 1000, c0 = 40, c1 = 300, c2 = 3;
  const auto x = random_floats(n * c0, 81), W0 = random_floats(c1 * c0, 82, 0.3f), W1 = random_floats(c1 * c1, 83, 0.1f),
             W2 = random_floats(c2 * c1, 84, 0.1f), b0 = random_floats(c1, 85), b1 = random_floats(c1, 86),
             b2 = random_floats(c2, 87);
  Tape<float> tape;
  NoRecord<float> off(tape);
  MatmulPrecisionScope<float> bf16(tape, MatmulPrecision::kBFloat16);
  const Var<float> xv = tape.constant(x.data(), n, c0);
  const std::array<Var<float>, 3> w{tape.constant(W0.data(), c1, c0), tape.constant(W1.data(), c1, c1),
                                    tape.constant(W2.data(), c2, c1)};
  const std::array<Var<float>, 3> b{tape.constant(b0.data(), 1, c1), tape.constant(b1.data(), 1, c1),
                                    tape.constant(b2.data(), 1, c2)};
  const Var<float> fused = mlp(tape, xv, std::span<const Var<float>>(w), std::span<const Var<float>>(b), false);
  const Var<float> layered = linear(tape, linear_relu(tape, linear_relu(tape, xv, w[0], b[0]), w[1], b[1]), w[2], b[2]);
  float worst = 0, largest = 0;
  for (int64_t k = 0; k < fused.size(); ++k) {
    worst = std::max(worst, std::abs(fused.value[k] - layered.value[k]));
    largest = std::max(largest, std::abs(layered.value[k]));
  }
  EXPECT_GT(largest, 0.1f);
  EXPECT_LE(worst, 1e-5f * largest);
  // And it is not the float result: the kernel ran.
  MatmulPrecisionScope<float> f32(tape, MatmulPrecision::kFloat32);
  const Var<float> exact = mlp(tape, xv, std::span<const Var<float>>(w), std::span<const Var<float>>(b), false);
  EXPECT_NE(std::memcmp(exact.value, fused.value, sizeof(float) * fused.size()), 0);
  // bf16 on a recording tape throws, as in linear.
  tape.set_recording(true);
  tape.set_matmul_precision(MatmulPrecision::kBFloat16);
  EXPECT_THROW(mlp(tape, xv, std::span<const Var<float>>(w), std::span<const Var<float>>(b), false), CheckError);
}

TEST(Bf16Linear, NarrowProductsStayFloat) {
  // Cin = 3 (the model's transposes by an identity and its 3-D maps) and Cout = 3.
  for (const Shape& s : {Shape{50, 3, 32}, Shape{50, 32, 3}}) {
    const auto x = random_floats(s.n * s.cin, 61), W = random_floats(s.cout * s.cin, 62);
    Tape<float> tape;
    NoRecord<float> off(tape);
    const Var<float> xv = tape.constant(x.data(), s.n, s.cin), Wv = tape.constant(W.data(), s.cout, s.cin);
    const Var<float> y32 = linear(tape, xv, Wv);
    tape.set_matmul_precision(MatmulPrecision::kBFloat16);
    const Var<float> y16 = linear(tape, xv, Wv);
    EXPECT_EQ(std::memcmp(y32.value, y16.value, sizeof(float) * y32.size()), 0);
  }
}

TEST(Bf16Linear, RecordingTapeOrDoubleTapeThrows) {
  const auto x = random_floats(20 * 16, 71), W = random_floats(16 * 16, 72);
  Tape<float> tape;
  tape.set_matmul_precision(MatmulPrecision::kBFloat16);
  const Var<float> xv = tape.constant(x.data(), 20, 16), Wv = tape.leaf(W.data(), 16, 16);
  EXPECT_THROW(linear(tape, xv, Wv), CheckError);
  EXPECT_THROW(linear_relu(tape, xv, Wv), CheckError);
  {
    NoRecord<float> off(tape);
    EXPECT_NO_THROW(linear(tape, xv, Wv));
  }
  EXPECT_THROW(linear(tape, xv, Wv), CheckError);  // recording again after the scope
  tape.set_matmul_precision(MatmulPrecision::kFloat32);
  EXPECT_NO_THROW(linear(tape, xv, Wv));

  Tape<double> dtape;
  NoRecord<double> off(dtape);
  MatmulPrecisionScope<double> bf16(dtape, MatmulPrecision::kBFloat16);
  const std::vector<double> xd(20 * 16, 1.0), Wd(16 * 16, 0.5);
  EXPECT_THROW(linear(dtape, dtape.constant(xd.data(), 20, 16), dtape.constant(Wd.data(), 16, 16)), CheckError);
}

TEST(Bf16Linear, PrecisionNamesParse) {
  EXPECT_EQ(parse_matmul_precision("bf16"), MatmulPrecision::kBFloat16);
  EXPECT_EQ(parse_matmul_precision("bfloat16"), MatmulPrecision::kBFloat16);
  EXPECT_EQ(parse_matmul_precision("float32"), MatmulPrecision::kFloat32);
  EXPECT_STREQ(matmul_precision_name(MatmulPrecision::kBFloat16), "bf16");
  EXPECT_THROW(parse_matmul_precision("fp16"), std::invalid_argument);
}

}  // namespace
}  // namespace layersnet::ad
