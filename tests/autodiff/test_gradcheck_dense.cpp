// Gradient checks of the dense ops (autodiff/ops_dense.h), plus forward values against
// plain Eigen (a gradient check alone cannot catch a wrong forward with a matching backward).
#include "autodiff/ops_dense.h"
#include "gradcheck_registry.h"

#include <omp.h>

#include <cmath>

namespace layersnet::ad::testing {

namespace {

using Vars = std::vector<Var<double>>;

// Moves entries within `gap` of `at` away from it (keeps finite differences off a kink).
RowMat<double> away_from(RowMat<double> m, double at, double gap) {
  for (int64_t k = 0; k < m.size(); ++k) {
    double& v = m.data()[k];
    if (std::abs(v - at) < gap) v = at + (v >= at ? gap : -gap);
  }
  return m;
}

// A 4-op chain exercising every broadcast shape of a binary op.
template <class Op>
void check_broadcasts(OpKind kind, Op op, double b_lo = -1, double b_hi = 1) {
  const auto f = [op](Tape<double>& t, const Vars& v) {
    Var<double> y = op(t, v[0], v[1]);  // (N, C) . (N, C)
    y = op(t, y, v[2]);                 // . (1, C)
    y = op(t, y, v[3]);                 // . (N, 1)
    return op(t, y, v[4]);              // . (1, 1)
  };
  expect_gradcheck(kind, f,
                   {{random_matrix(5, 4, 1)},
                    {random_matrix(5, 4, 2, b_lo, b_hi)},
                    {random_matrix(1, 4, 3, b_lo, b_hi)},
                    {random_matrix(5, 1, 4, b_lo, b_hi)},
                    {random_matrix(1, 1, 5, b_lo, b_hi)}});
}

template <class Op>
void check_one_row(OpKind kind, Op op, double b_lo = -1, double b_hi = 1) {
  const auto f = [op](Tape<double>& t, const Vars& v) { return op(t, op(t, v[0], v[1]), v[2]); };
  // (1, C) . (1, C) [b constant] . (1, 1)
  expect_gradcheck(kind, f,
                   {{random_matrix(1, 3, 6)}, {random_matrix(1, 3, 7, b_lo, b_hi), false},
                    {random_matrix(1, 1, 8, b_lo, b_hi)}});
}

// Values in [0.5, 2] with alternating signs: divisors well away from 0.
RowMat<double> signed_magnitudes(int64_t rows, int64_t cols, unsigned seed) {
  RowMat<double> m = random_matrix(rows, cols, seed, 0.5, 2.0);
  for (int64_t k = 0; k < m.size(); k += 2) m.data()[k] = -m.data()[k];
  return m;
}

}  // namespace

// ---- linear -------------------------------------------------------------------------------

GRADCHECK_TEST(Linear, WithBias) {
  const auto f = [](Tape<double>& t, const Vars& v) { return linear(t, v[0], v[1], v[2]); };
  expect_gradcheck(OpKind::Linear, f, {{random_matrix(6, 5, 1)}, {random_matrix(3, 5, 2)}, {random_matrix(1, 3, 3)}});
}

GRADCHECK_TEST(Linear, WithoutBiasAndConstantInput) {
  const auto f = [](Tape<double>& t, const Vars& v) { return linear(t, v[0], v[1]); };
  expect_gradcheck(OpKind::Linear, f, {{random_matrix(4, 3, 4), false}, {random_matrix(2, 3, 5)}});
}

GRADCHECK_TEST(Linear, OneRowAndConstantWeights) {
  const auto f = [](Tape<double>& t, const Vars& v) { return linear(t, v[0], v[1], v[2]); };
  expect_gradcheck(OpKind::Linear, f,
                   {{random_matrix(1, 7, 6)}, {random_matrix(4, 7, 7), false}, {random_matrix(1, 4, 8)}});
}

GRADCHECK_TEST(Linear, LargeMagnitudes) {
  const auto f = [](Tape<double>& t, const Vars& v) { return linear(t, v[0], v[1], v[2]); };
  GradcheckOptions opt;
  opt.eps = 1e-3;  // linear in each input: central differences are exact up to rounding
  opt.atol = 1e-4;
  expect_gradcheck(OpKind::Linear, f,
                   {{random_matrix(3, 4, 9, -1e4, 1e4)}, {random_matrix(2, 4, 10, -1e3, 1e3)},
                    {random_matrix(1, 2, 11, -1e5, 1e5)}},
                   opt);
}

GRADCHECK_TEST(Linear, WithResidual) {
  const auto f = [](Tape<double>& t, const Vars& v) { return linear_add(t, v[0], v[1], v[2], v[3]); };
  const RowMat<double> x = random_matrix(6, 5, 93), w = random_matrix(3, 5, 94), b = random_matrix(1, 3, 95),
                       r = random_matrix(6, 3, 96);
  const GradcheckReport rep = expect_gradcheck(OpKind::Linear, f, {{x}, {w}, {b}, {r}});
  const RowMat<double> expected = ((x * w.transpose()).rowwise() + b.row(0)) + r;
  EXPECT_TRUE(rep.output.isApprox(expected, 1e-12));
}

GRADCHECK_TEST(Linear, WithResidualWithoutBiasOverThreads) {
  // Enough rows for several chunks on the threads; the residual is also the GEMM's input, as
  // in the model's memory streams (r = R + x W_rᵀ + R W_mᵀ).
  const auto f = [](Tape<double>& t, const Vars& v) { return linear_add(t, v[0], v[1], {}, v[0]); };
  const std::vector<GradcheckInput> in = {{random_matrix(700, 8, 97)}, {random_matrix(8, 8, 98)}};
  const GradcheckReport rep = expect_gradcheck(OpKind::Linear, f, in, large_options());
  const RowMat<double> x = random_matrix(700, 8, 97);
  EXPECT_TRUE(rep.output.isApprox(x * random_matrix(8, 8, 98).transpose() + x, 1e-12));
  expect_thread_count_invariant(f, in);
}

TEST(Linear, RejectsAResidualOfAnotherShape) {
  Tape<double> tape;
  const RowMat<double> x = random_matrix(4, 3, 99), w = random_matrix(2, 3, 100), r = random_matrix(4, 3, 101);
  const Var<double> xv = tape.leaf(x.data(), 4, 3), wv = tape.leaf(w.data(), 2, 3), rv = tape.leaf(r.data(), 4, 3);
  EXPECT_THROW(linear_add(tape, xv, wv, {}, rv), CheckError);
  EXPECT_THROW(linear_add(tape, xv, wv, {}, Var<double>{}), CheckError);
}

// ---- mlp ----------------------------------------------------------------------------------

namespace {

// The same layers as separate linear / linear_relu ops: the reference of the fused op.
Var<double> mlp_by_layers(Tape<double>& t, Var<double> x, const Vars& w, const Vars& b, bool final_relu) {
  for (std::size_t i = 0; i < w.size(); ++i)
    x = (i + 1 < w.size() || final_relu) ? linear_relu(t, x, w[i], b[i]) : linear(t, x, w[i], b[i]);
  return x;
}

}  // namespace

GRADCHECK_TEST(Mlp, ThreeLayersMatchTheLayersOneByOne) {
  // Pre-activations kept off the ReLU's kink: biases of 0.3 in magnitude, small weights.
  const auto f = [](Tape<double>& t, const Vars& v) {
    const Vars w{v[1], v[2], v[3]}, b{v[4], Var<double>{}, v[5]};
    return mlp(t, v[0], std::span<const Var<double>>(w), std::span<const Var<double>>(b), false);
  };
  const std::vector<GradcheckInput> in = {{random_matrix(7, 4, 110)},    {random_matrix(6, 4, 111)},
                                          {random_matrix(5, 6, 112)},    {random_matrix(2, 5, 113)},
                                          {random_matrix(1, 6, 114)},    {random_matrix(1, 2, 115)}};
  const GradcheckReport rep = expect_gradcheck(OpKind::Mlp, f, in);
  const auto g = [](Tape<double>& t, const Vars& v) {
    return mlp_by_layers(t, v[0], {v[1], v[2], v[3]}, {v[4], Var<double>{}, v[5]}, false);
  };
  const GradcheckReport ref = gradcheck(g, in, {});
  EXPECT_TRUE(rep.output.isApprox(ref.output, 1e-12));
  ASSERT_EQ(rep.gradients.size(), ref.gradients.size());
  for (std::size_t i = 0; i < ref.gradients.size(); ++i)
    EXPECT_TRUE(rep.gradients[i].isApprox(ref.gradients[i], 1e-12)) << "input " << i;
}

GRADCHECK_TEST(Mlp, OneLayerWithFinalReluAndConstantInput) {
  const auto f = [](Tape<double>& t, const Vars& v) {
    const Vars w{v[1]}, b{v[2]};
    return mlp(t, v[0], std::span<const Var<double>>(w), std::span<const Var<double>>(b), true);
  };
  const RowMat<double> x = random_matrix(5, 3, 116), w = random_matrix(4, 3, 117), b = random_matrix(1, 4, 118);
  const GradcheckReport rep = expect_gradcheck(OpKind::Mlp, f, {{x, false}, {w}, {b}});
  EXPECT_TRUE(rep.output.isApprox(((x * w.transpose()).rowwise() + b.row(0)).cwiseMax(0.0), 1e-12));
}

GRADCHECK_TEST(Mlp, ManyBlocksOverThreads) {
  // More rows than one cache block and one chunk, so blocks, chunks and threads all split.
  const auto f = [](Tape<double>& t, const Vars& v) {
    const Vars w{v[1], v[2]}, b{v[3], v[4]};
    return mlp(t, v[0], std::span<const Var<double>>(w), std::span<const Var<double>>(b), false);
  };
  const std::vector<GradcheckInput> in = {{random_matrix(5000, 6, 119)},
                                          {random_matrix(300, 6, 120)},
                                          {random_matrix(3, 300, 121, -0.1, 0.1)},
                                          {random_matrix(1, 300, 122)},
                                          {random_matrix(1, 3, 123)}};
  const GradcheckReport rep = expect_gradcheck(OpKind::Mlp, f, in, large_options());
  const auto g = [](Tape<double>& t, const Vars& v) { return mlp_by_layers(t, v[0], {v[1], v[2]}, {v[3], v[4]}, false); };
  GradcheckOptions one;
  one.max_coords = 1;
  const GradcheckReport ref = gradcheck(g, in, one);
  EXPECT_TRUE(rep.output.isApprox(ref.output, 1e-12));
  for (std::size_t i = 0; i < ref.gradients.size(); ++i)
    EXPECT_TRUE(rep.gradients[i].isApprox(ref.gradients[i], 1e-12)) << "input " << i;
  expect_thread_count_invariant(f, in);
}

TEST(Mlp, RejectsMismatchedLayers) {
  Tape<double> tape;
  const RowMat<double> x = random_matrix(4, 3, 124), w0 = random_matrix(5, 3, 125), w1 = random_matrix(2, 4, 126);
  const Var<double> xv = tape.leaf(x.data(), 4, 3), w0v = tape.leaf(w0.data(), 5, 3), w1v = tape.leaf(w1.data(), 2, 4);
  const Vars w{w0v, w1v}, b{Var<double>{}, Var<double>{}}, one_bias{Var<double>{}};
  EXPECT_THROW(mlp(tape, xv, std::span<const Var<double>>(w), std::span<const Var<double>>(b), false), CheckError);
  EXPECT_THROW(mlp(tape, xv, std::span<const Var<double>>(w), std::span<const Var<double>>(one_bias), false), CheckError);
}

GRADCHECK_TEST(LinearRelu, MatchesLinearThenRelu) {
  const auto f = [](Tape<double>& t, const Vars& v) { return linear_relu(t, v[0], v[1], v[2]); };
  // Inputs chosen so no pre-activation is within the finite-difference step of 0.
  const RowMat<double> x = random_matrix(6, 5, 90), w = random_matrix(4, 5, 91), b = random_matrix(1, 4, 92);
  const GradcheckReport rep = expect_gradcheck(OpKind::LinearRelu, f, {{x}, {w}, {b}});
  const RowMat<double> z = (x * w.transpose()).rowwise() + b.row(0);
  ASSERT_GT(z.cwiseAbs().minCoeff(), 1e-4);
  EXPECT_TRUE(rep.output.isApprox(z.cwiseMax(0.0), 1e-12));
  EXPECT_GT((z.array() < 0).count(), 0);  // both sides of the kink are exercised
  EXPECT_GT((z.array() > 0).count(), 0);
}

GRADCHECK_TEST(LinearRelu, OneRowNoBiasAndChunkedRows) {
  const auto f = [](Tape<double>& t, const Vars& v) {
    // 1 row without bias, and 3000 rows (3 chunks with per-chunk masked partials).
    return add(t, sum_all(t, linear_relu(t, v[0], v[1])), sum_all(t, linear_relu(t, v[2], v[1], v[3])));
  };
  GradcheckOptions opt;
  opt.max_coords = 24;
  expect_gradcheck(OpKind::LinearRelu, f,
                   {{random_matrix(1, 3, 93)}, {random_matrix(2, 3, 94)}, {random_matrix(3000, 3, 95)},
                    {random_matrix(1, 2, 96)}},
                   opt);
}

// ---- add, sub, mul, div -----------------------------------------------------------------

GRADCHECK_TEST(Add, SameShapeAndEveryBroadcast) {
  check_broadcasts(OpKind::Add, [](Tape<double>& t, const Var<double>& a, const Var<double>& b) { return add(t, a, b); });
}

GRADCHECK_TEST(Add, OneRowAndConstantOperand) {
  check_one_row(OpKind::Add, [](Tape<double>& t, const Var<double>& a, const Var<double>& b) { return add(t, a, b); });
}

GRADCHECK_TEST(Sub, SameShapeAndEveryBroadcast) {
  check_broadcasts(OpKind::Sub, [](Tape<double>& t, const Var<double>& a, const Var<double>& b) { return sub(t, a, b); });
}

GRADCHECK_TEST(Sub, OneRowAndConstantOperand) {
  check_one_row(OpKind::Sub, [](Tape<double>& t, const Var<double>& a, const Var<double>& b) { return sub(t, a, b); });
}

GRADCHECK_TEST(Mul, SameShapeAndEveryBroadcast) {
  check_broadcasts(OpKind::Mul, [](Tape<double>& t, const Var<double>& a, const Var<double>& b) { return mul(t, a, b); });
}

GRADCHECK_TEST(Mul, OneRowAndConstantOperand) {
  check_one_row(OpKind::Mul, [](Tape<double>& t, const Var<double>& a, const Var<double>& b) { return mul(t, a, b); });
}

GRADCHECK_TEST(Mul, SquareOfOneVariable) {  // both operands are the same tensor: grads add up
  const auto f = [](Tape<double>& t, const Vars& v) { return mul(t, v[0], v[0]); };
  expect_gradcheck(OpKind::Mul, f, {{random_matrix(3, 3, 12)}});
}

GRADCHECK_TEST(Div, SameShapeAndEveryBroadcast) {
  const auto f = [](Tape<double>& t, const Vars& v) {
    Var<double> y = div(t, v[0], v[1]);
    y = div(t, y, v[2]);
    y = div(t, y, v[3]);
    return div(t, y, v[4]);
  };
  expect_gradcheck(OpKind::Div, f,
                   {{random_matrix(5, 4, 13)}, {signed_magnitudes(5, 4, 14)}, {signed_magnitudes(1, 4, 15)},
                    {signed_magnitudes(5, 1, 16)}, {signed_magnitudes(1, 1, 17)}});
}

GRADCHECK_TEST(Div, OneRowAndSmallDivisor) {
  const auto f = [](Tape<double>& t, const Vars& v) { return div(t, v[0], v[1]); };
  GradcheckOptions opt;
  opt.eps = 1e-9;  // d/db of a/b with b = 1e-3 has curvature ~1e9: keep the step tiny
  opt.atol = 1e-5;  // ...which costs rounding noise ~1e-13 * |a/b| / eps
  opt.rtol = 1e-4;
  RowMat<double> b(1, 3);
  b << 1e-3, -2e-3, 5.0;
  expect_gradcheck(OpKind::Div, f, {{random_matrix(1, 3, 18)}, {b}}, opt);
}

// ---- scale, relu, hinge_sq --------------------------------------------------------------

GRADCHECK_TEST(Scale, NegativeFactorAndLargeMagnitudes) {
  const auto f = [](Tape<double>& t, const Vars& v) { return scale(t, scale(t, v[0], -2.5), 1e3); };
  GradcheckOptions opt;
  opt.eps = 1e-3;
  opt.atol = 1e-5;
  expect_gradcheck(OpKind::Scale, f, {{random_matrix(4, 3, 19, -1e5, 1e5)}}, opt);
}

GRADCHECK_TEST(Scale, OneRow) {
  const auto f = [](Tape<double>& t, const Vars& v) { return scale(t, v[0], 0.5); };
  expect_gradcheck(OpKind::Scale, f, {{random_matrix(1, 1, 20)}});
}

GRADCHECK_TEST(Relu, MixedSignsAwayFromTheKink) {
  const auto f = [](Tape<double>& t, const Vars& v) { return relu(t, v[0]); };
  expect_gradcheck(OpKind::Relu, f, {{away_from(random_matrix(6, 5, 21), 0, 1e-3)}});
}

GRADCHECK_TEST(Relu, OneRowLargeMagnitudes) {
  const auto f = [](Tape<double>& t, const Vars& v) { return relu(t, v[0]); };
  GradcheckOptions opt;
  opt.eps = 1e-2;  // piecewise linear, entries >= 1 away from the kink: large steps are exact
  opt.atol = 1e-6;
  expect_gradcheck(OpKind::Relu, f, {{away_from(random_matrix(1, 8, 22, -1e6, 1e6), 0, 1)}}, opt);
}

GRADCHECK_TEST(HingeSq, NearTheThresholdOnBothSides) {
  const auto f = [](Tape<double>& t, const Vars& v) { return hinge_sq(t, v[0], 0.001); };
  RowMat<double> x(2, 4);
  // Just below / above the threshold (1e-4 away, 100x the difference step), and far off.
  x << 0.001 - 1e-4, 0.001 + 1e-4, 0.001 - 1e-5, 0.001 + 1e-5, -0.5, 0.7, -3.0, 2.0;
  expect_gradcheck(OpKind::HingeSq, f, {{x}});
}

GRADCHECK_TEST(HingeSq, OneRowLargeMagnitudes) {
  const auto f = [](Tape<double>& t, const Vars& v) { return hinge_sq(t, v[0], -2.0); };
  GradcheckOptions opt;
  opt.eps = 1e-4;  // quadratic: central differences exact up to rounding
  opt.atol = 1e-3;
  expect_gradcheck(OpKind::HingeSq, f, {{random_matrix(1, 6, 23, -1e4, 1e4)}}, opt);
}

// ---- layer_norm ---------------------------------------------------------------------------

GRADCHECK_TEST(LayerNorm, RandomRowsWithAffine) {
  const auto f = [](Tape<double>& t, const Vars& v) { return layer_norm(t, v[0], v[1], v[2]); };
  expect_gradcheck(OpKind::LayerNorm, f,
                   {{random_matrix(5, 6, 24, -2, 3)}, {random_matrix(1, 6, 25, 0.5, 1.5)}, {random_matrix(1, 6, 26)}});
}

GRADCHECK_TEST(LayerNorm, ConstantRowsStayFinite) {
  // Row 0 constant, row 1 constant zero, row 2 random: var = 0 -> rstd = 1/sqrt(eps).
  RowMat<double> x = random_matrix(3, 5, 27);
  x.row(0).setConstant(0.37);
  x.row(1).setZero();
  const auto f = [](Tape<double>& t, const Vars& v) { return layer_norm(t, v[0], v[1], v[2]); };
  GradcheckOptions opt;
  opt.rtol = 1e-4;  // gradients ~ rstd = 316 here
  const GradcheckReport rep = expect_gradcheck(
      OpKind::LayerNorm, f, {{x}, {random_matrix(1, 5, 28, 0.5, 1.5)}, {random_matrix(1, 5, 29)}}, opt);
  // A constant row normalises to 0, so its output is beta exactly.
  const RowMat<double> beta = random_matrix(1, 5, 29);
  EXPECT_EQ(rep.output.row(0), beta);
  EXPECT_EQ(rep.output.row(1), beta);
}

GRADCHECK_TEST(LayerNorm, OneRowNoAffineLargeMean) {
  const auto f = [](Tape<double>& t, const Vars& v) { return layer_norm(t, v[0], Var<double>{}, Var<double>{}); };
  RowMat<double> x = random_matrix(1, 8, 30);
  x.array() += 1e4;  // mean 1e4, spread 1: the two-pass variance keeps the precision
  GradcheckOptions opt;
  opt.eps = 1e-5;
  opt.atol = 1e-5;
  opt.rtol = 1e-4;
  const GradcheckReport rep = expect_gradcheck(OpKind::LayerNorm, f, {{x}}, opt);
  EXPECT_NEAR(rep.output.mean(), 0.0, 1e-9);
  EXPECT_NEAR(rep.output.squaredNorm() / 8, 1.0, 1e-4);  // var / (var + eps) with var ~ 0.3
}

GRADCHECK_TEST(LayerNorm, SingleColumnAndLargeScale) {
  // C = 1: every row is constant; C = 4 with entries ~1e3: rstd ~1e-3.
  const auto f = [](Tape<double>& t, const Vars& v) {
    return add(t, layer_norm(t, v[0], v[1], v[2]), sum_all(t, layer_norm(t, v[3], Var<double>{}, Var<double>{})));
  };
  GradcheckOptions opt;
  opt.eps = 1e-4;
  opt.rtol = 1e-4;
  expect_gradcheck(OpKind::LayerNorm, f,
                   {{random_matrix(4, 1, 31)}, {random_matrix(1, 1, 32)}, {random_matrix(1, 1, 33)},
                    {random_matrix(3, 4, 34, -1e3, 1e3)}},
                   opt);
}

// ---- concat_cols, slice_cols ------------------------------------------------------------

GRADCHECK_TEST(ConcatCols, ThreeWidthsOneConstant) {
  const auto f = [](Tape<double>& t, const Vars& v) { return concat_cols(t, {v[0], v[1], v[2]}); };
  expect_gradcheck(OpKind::ConcatCols, f,
                   {{random_matrix(4, 2, 35)}, {random_matrix(4, 3, 36), false}, {random_matrix(4, 1, 37)}});
}

GRADCHECK_TEST(ConcatCols, OneRowSameInputTwice) {
  const auto f = [](Tape<double>& t, const Vars& v) { return concat_cols(t, {v[0], v[1], v[0]}); };
  expect_gradcheck(OpKind::ConcatCols, f, {{random_matrix(1, 3, 38)}, {random_matrix(1, 2, 39)}});
}

GRADCHECK_TEST(SliceCols, SplitIntoThreeAndRecombine) {
  // Split (N, 6) into [0,1), [1,4), [4,6) and weight each differently.
  const auto f = [](Tape<double>& t, const Vars& v) {
    Var<double> a = slice_cols(t, v[0], 0, 1), b = slice_cols(t, v[0], 1, 4), c = slice_cols(t, v[0], 4, 6);
    return concat_cols(t, {scale(t, c, 2.0), a, mul(t, b, b)});
  };
  expect_gradcheck(OpKind::SliceCols, f, {{random_matrix(3, 6, 40)}});
}

GRADCHECK_TEST(SliceCols, OneRowFullWidth) {
  const auto f = [](Tape<double>& t, const Vars& v) { return slice_cols(t, v[0], 0, 4); };
  expect_gradcheck(OpKind::SliceCols, f, {{random_matrix(1, 4, 41)}});
}

// ---- reductions ---------------------------------------------------------------------------

GRADCHECK_TEST(SumAll, SumAndMean) {
  const auto f = [](Tape<double>& t, const Vars& v) { return add(t, sum_all(t, v[0]), mean_all(t, v[1])); };
  expect_gradcheck(OpKind::SumAll, f, {{random_matrix(4, 3, 42)}, {random_matrix(5, 2, 43)}});
}

GRADCHECK_TEST(SumAll, OneByOne) {
  const auto f = [](Tape<double>& t, const Vars& v) { return mean_all(t, v[0]); };
  expect_gradcheck(OpKind::SumAll, f, {{random_matrix(1, 1, 44)}});
}

GRADCHECK_TEST(ColSum, SumAndMean) {
  const auto f = [](Tape<double>& t, const Vars& v) { return add(t, col_sum(t, v[0]), col_mean(t, v[1])); };
  expect_gradcheck(OpKind::ColSum, f, {{random_matrix(4, 3, 45)}, {random_matrix(7, 3, 46)}});
}

GRADCHECK_TEST(ColSum, OneRow) {
  const auto f = [](Tape<double>& t, const Vars& v) { return col_mean(t, v[0]); };
  expect_gradcheck(OpKind::ColSum, f, {{random_matrix(1, 5, 47)}});
}

GRADCHECK_TEST(RowSum, SumAndMean) {
  const auto f = [](Tape<double>& t, const Vars& v) { return add(t, row_sum(t, v[0]), row_mean(t, v[1])); };
  expect_gradcheck(OpKind::RowSum, f, {{random_matrix(4, 3, 48)}, {random_matrix(4, 6, 49)}});
}

GRADCHECK_TEST(RowSum, OneRowOneColumn) {
  const auto f = [](Tape<double>& t, const Vars& v) { return add(t, row_sum(t, v[0]), row_mean(t, v[1])); };
  expect_gradcheck(OpKind::RowSum, f, {{random_matrix(1, 4, 50)}, {random_matrix(1, 1, 51)}});
}

// ---- squared_error ----------------------------------------------------------------------

GRADCHECK_TEST(SquaredError, BothSidesNeedGradients) {
  const auto f = [](Tape<double>& t, const Vars& v) { return squared_error(t, v[0], v[1]); };
  expect_gradcheck(OpKind::SquaredError, f, {{random_matrix(5, 3, 52)}, {random_matrix(5, 3, 53)}});
}

GRADCHECK_TEST(SquaredError, OneRowConstantTargetLargeMagnitudes) {
  const auto f = [](Tape<double>& t, const Vars& v) { return mean_all(t, squared_error(t, v[0], v[1])); };
  GradcheckOptions opt;
  opt.eps = 1e-3;
  opt.atol = 1e-4;
  expect_gradcheck(OpKind::SquaredError, f,
                   {{random_matrix(1, 3, 54, -1e4, 1e4)}, {random_matrix(1, 3, 55, -1e4, 1e4), false}}, opt);
}

GRADCHECK_TEST(SquaredError, IdenticalInputsGiveZeroGradient) {
  const auto f = [](Tape<double>& t, const Vars& v) { return squared_error(t, v[0], v[1]); };
  const RowMat<double> x = random_matrix(2, 3, 56);
  const GradcheckReport rep = expect_gradcheck(OpKind::SquaredError, f, {{x}, {x}});
  EXPECT_EQ(rep.output.norm(), 0.0);
  EXPECT_EQ(rep.gradients[0].norm(), 0.0);
}

// ---- forward values and whole chains ------------------------------------------------------

TEST(DenseForward, MatchesPlainEigen) {
  Tape<double> t;
  NoRecord<double> off(t);
  const RowMat<double> X = random_matrix(5, 4, 60), W = random_matrix(3, 4, 61), b = random_matrix(1, 3, 62);
  const RowMat<double> B = random_matrix(5, 4, 63, 0.5, 2), r = random_matrix(1, 4, 64), c = random_matrix(5, 1, 65);
  const auto x = t.constant(X.data(), 5, 4), w = t.constant(W.data(), 3, 4), bb = t.constant(b.data(), 1, 3);
  const auto vb = t.constant(B.data(), 5, 4), vr = t.constant(r.data(), 1, 4), vc = t.constant(c.data(), 5, 1);
  const double tol = 1e-12;

  EXPECT_TRUE(linear(t, x, w, bb).val().isApprox((X * W.transpose()).rowwise() + b.row(0), tol));
  EXPECT_TRUE(linear(t, x, w).val().isApprox(X * W.transpose(), tol));
  EXPECT_TRUE(sub(t, x, vr).val().isApprox(X.rowwise() - r.row(0), tol));
  EXPECT_TRUE(mul(t, x, vc).val().isApprox((X.array().colwise() * c.col(0).array()).matrix(), tol));
  EXPECT_TRUE(div(t, x, vb).val().isApprox((X.array() / B.array()).matrix(), tol));
  EXPECT_TRUE(relu(t, x).val().isApprox(X.cwiseMax(0.0), tol));
  EXPECT_TRUE(hinge_sq(t, x, 0.25).val().isApprox((X.array() - 0.25).min(0.0).square().matrix(), tol));
  EXPECT_TRUE(col_sum(t, x).val().isApprox(X.colwise().sum(), tol));
  EXPECT_TRUE(row_mean(t, x).val().isApprox(X.rowwise().mean(), tol));
  EXPECT_NEAR(mean_all(t, x).scalar(), X.mean(), tol);
  EXPECT_TRUE(squared_error(t, x, vb).val().isApprox((X - B).rowwise().squaredNorm(), tol));
  EXPECT_TRUE(slice_cols(t, x, 1, 3).val().isApprox(X.middleCols(1, 2), tol));
  const auto cat = concat_cols(t, {x, vc});
  EXPECT_TRUE(cat.val().leftCols(4).isApprox(X, tol));
  EXPECT_TRUE(cat.val().col(4).isApprox(c.col(0), tol));

  const RowMat<double> ln = layer_norm(t, x, Var<double>{}, Var<double>{}, 0.0 + 1e-12).val();
  for (int r_ = 0; r_ < 5; ++r_) {
    EXPECT_NEAR(ln.row(r_).mean(), 0.0, 1e-12);
    EXPECT_NEAR((ln.row(r_).array() * ln.row(r_).array()).mean(), 1.0, 1e-9);
  }
}

TEST(DenseForward, LinearInChunksMatchesPlainEigen) {
  // N = 5000 runs linear in 4 row chunks with per-chunk dW/db partials.
  Tape<double> t;
  const RowMat<double> X = random_matrix(5000, 7, 80), W = random_matrix(3, 7, 81), b = random_matrix(1, 3, 82);
  const RowMat<double> G = random_matrix(5000, 3, 83);
  const auto x = t.leaf(X.data(), 5000, 7), w = t.leaf(W.data(), 3, 7), bb = t.leaf(b.data(), 1, 3);
  const auto y = linear(t, x, w, bb);
  EXPECT_TRUE(y.val().isApprox((X * W.transpose()).rowwise() + b.row(0), 1e-12));
  y.grd() = G;
  t.backward_seeded();
  EXPECT_TRUE(x.grd().isApprox(G * W, 1e-12));
  EXPECT_TRUE(w.grd().isApprox(G.transpose() * X, 1e-12));
  EXPECT_TRUE(bb.grd().isApprox(G.colwise().sum(), 1e-12));
}

TEST(DenseForward, ZeroRowTensorsFlowThrough) {
  // N = 0 (e.g. no vertex of a garment in a batch): every op returns an empty result and
  // backward leaves parameter gradients at zero.
  Tape<double> t;
  const RowMat<double> W = random_matrix(2, 3, 84), g1 = RowMat<double>::Ones(1, 2);
  const auto x = t.leaf(nullptr, 0, 3), w = t.leaf(W.data(), 2, 3), gamma = t.leaf(g1.data(), 1, 2);
  Var<double> h = relu(t, linear(t, x, w));
  h = layer_norm(t, h, gamma, Var<double>{});
  h = concat_cols(t, {h, slice_cols(t, x, 0, 1)});
  const Var<double> loss = add(t, mean_all(t, squared_error(t, h, h)), sum_all(t, col_mean(t, row_sum(t, h))));
  EXPECT_EQ(h.rows, 0);
  EXPECT_EQ(h.cols, 3);
  t.backward(loss);
  EXPECT_EQ(loss.scalar(), 0.0);
  EXPECT_EQ(w.grd().norm(), 0.0);
  EXPECT_EQ(gamma.grd().norm(), 0.0);
}

TEST(DenseForward, ReluAtExactlyZeroHasZeroGradient) {
  Tape<double> t;
  const RowMat<double> z = RowMat<double>::Zero(1, 3);
  const auto x = t.leaf(z.data(), 1, 3);
  const auto y = sum_all(t, relu(t, x));
  t.backward(y);
  EXPECT_EQ(y.scalar(), 0.0);
  for (int k = 0; k < 3; ++k) EXPECT_EQ(x.grad[k], 0.0);
}

TEST(DenseForward, BadShapesThrow) {
  Tape<double> t;
  const RowMat<double> a = random_matrix(3, 4, 66);
  const auto x = t.constant(a.data(), 3, 4), wrong = t.constant(a.data(), 2, 2);
  EXPECT_THROW(add(t, x, wrong), CheckError);
  EXPECT_THROW(linear(t, x, wrong), CheckError);
  EXPECT_THROW(slice_cols(t, x, 2, 5), CheckError);
  EXPECT_THROW(squared_error(t, x, wrong), CheckError);
}

TEST(LayerNormRows, EachRowIsItsPlainLoopWhateverRowsSurroundIt) {
  // 37 rows (four groups of rows summed side by side and a tail of 5) of 23 columns: a row's mean
  // and variance are its columns added one by one, each squared term rounded first, and a row's
  // output and gradient are the same bits in the whole tensor as alone.
  const int64_t N = 37, C = 23;
  const float eps = 1e-5f;
  const RowMat<float> x = (random_matrix(N, C, 70, -2, 3).array() + 10.0).matrix().cast<float>();
  const RowMat<float> weights = random_matrix(N, C, 71).cast<float>();
  auto run = [&](int64_t r0, int64_t rows) {
    Tape<float> t;
    const RowMat<float> xs = x.middleRows(r0, rows), ws = weights.middleRows(r0, rows);
    const auto xv = t.leaf(xs.data(), rows, C);
    const auto y = layer_norm(t, xv, Var<float>{}, Var<float>{}, eps);
    t.backward(sum_all(t, mul(t, y, t.constant(ws.data(), rows, C))));
    return std::pair<RowMat<float>, RowMat<float>>{y.val(), xv.grd()};
  };
  const auto [y, dx] = run(0, N);
  for (int64_t r = 0; r < N; ++r) {
    float sum = 0, squares = 0;
    for (int64_t c = 0; c < C; ++c) sum += x(r, c);
    const float mean = sum / float(C);
    std::vector<float> squared(C);
    for (int64_t c = 0; c < C; ++c) squared[c] = (x(r, c) - mean) * (x(r, c) - mean);
    for (int64_t c = 0; c < C; ++c) squares += squared[c];
    const float rstd = 1.0f / std::sqrt(squares / float(C) + eps);
    for (int64_t c = 0; c < C; ++c) ASSERT_EQ(y(r, c), (x(r, c) - mean) * rstd) << "row " << r << ", column " << c;
    const auto [y_alone, dx_alone] = run(r, 1);
    EXPECT_EQ(RowMat<float>(y.row(r)), y_alone) << "row " << r;
    EXPECT_EQ(RowMat<float>(dx.row(r)), dx_alone) << "row " << r;
  }
}

TEST(DenseDeterminism, ReductionsAreIdenticalForOneAndTwoThreads) {
  // Large enough to run in parallel; column sums, LayerNorm gradients and linear's weight
  // and bias gradients must not depend on the thread count.
  const RowMat<double> a = random_matrix(3000, 40, 67), w = random_matrix(8, 40, 68);
  auto run = [&](int threads) {
    omp_set_num_threads(threads);
    Tape<float> t;
    const RowMat<float> af = a.cast<float>(), wf = w.cast<float>();
    const auto x = t.leaf(af.data(), af.rows(), af.cols()), W = t.leaf(wf.data(), 8, 40);
    const RowMat<float> bias = RowMat<float>::Zero(1, 8);
    const auto b = t.leaf(bias.data(), 1, 8);
    auto y = linear(t, layer_norm(t, x, Var<float>{}, Var<float>{}), W, b);
    auto loss = add(t, mean_all(t, mul(t, y, y)), sum_all(t, col_mean(t, x)));
    t.backward(loss);
    std::vector<float> out(x.grad, x.grad + x.size());
    out.insert(out.end(), b.grad, b.grad + 8);
    out.insert(out.end(), W.grad, W.grad + W.size());  // sums of per-chunk partials
    out.push_back(loss.scalar());
    return out;
  };
  const int max_threads = omp_get_max_threads();
  const auto one = run(1), two = run(2);
  omp_set_num_threads(max_threads);
  EXPECT_EQ(one, two);
}

TEST(DenseChain, MlpLayerNormLossDirectionalCheck) {
  // linear-relu-linear-LN-concat-slice-mse: the ops composed as in the model.
  const auto f = [](Tape<double>& t, const Vars& v) {
    Var<double> h = relu(t, linear(t, v[0], v[1], v[2]));
    h = layer_norm(t, linear(t, h, v[3]), v[4], v[5]);
    Var<double> both = concat_cols(t, {h, v[0]});
    Var<double> pred = slice_cols(t, both, 1, 4);
    return add(t, mean_all(t, squared_error(t, pred, v[6])), scale(t, sum_all(t, hinge_sq(t, h, 0.1)), 0.01));
  };
  const DirectionalReport rep = directional_gradcheck(
      f, {{random_matrix(6, 3, 70)}, {random_matrix(5, 3, 71)}, {random_matrix(1, 5, 72)}, {random_matrix(4, 5, 73)},
          {random_matrix(1, 4, 74, 0.5, 1.5)}, {random_matrix(1, 4, 75)}, {random_matrix(6, 3, 76), false}});
  EXPECT_TRUE(rep.ok) << rep.analytic << " vs " << rep.numeric;
}

TEST(Gradcheck, HarnessCatchesAWrongGradient) {
  // The harness must be able to fail: compare against a function whose forward is not
  // what its recorded backward says (add's backward, but the forward doubles a).
  const auto f = [](Tape<double>& t, const std::vector<Var<double>>& v) {
    Var<double> y = add(t, v[0], v[1]);
    y.val() += v[0].val();  // forward changed behind the tape's back
    return y;
  };
  const GradcheckReport rep = gradcheck(f, {{random_matrix(3, 3, 8)}, {random_matrix(3, 3, 9)}});
  EXPECT_FALSE(rep.ok);
}

}  // namespace layersnet::ad::testing
