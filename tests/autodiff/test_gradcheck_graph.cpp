// Gradient checks of the graph ops (autodiff/ops_graph.h): gather, scatter, segment
// reductions and the segment softmax, including 1-row tensors, empty segments, repeated
// indices and logits of +-80.
#include "autodiff/ops_graph.h"
#include "gradcheck_registry.h"

#include <omp.h>

#include <cmath>
#include <limits>
#include <vector>

namespace layersnet::ad::testing {

namespace {

using Idx = std::vector<int32_t>;

}  // namespace

// ---- gather_rows ------------------------------------------------------------------------

GRADCHECK_TEST(GatherRows, RepeatedAndUnusedRows) {
  const Idx idx = {3, 0, 3, 3, 1};  // row 2 unused, row 3 three times
  const auto f = [&](Tape<double>& t, const std::vector<Var<double>>& v) { return gather_rows(t, v[0], idx); };
  const GradcheckReport rep = expect_gradcheck(OpKind::GatherRows, f, {{random_matrix(4, 3, 11)}});
  EXPECT_EQ(rep.output.rows(), 5);
  EXPECT_EQ(rep.output(2, 1), random_matrix(4, 3, 11)(3, 1));
}

GRADCHECK_TEST(GatherRows, OneRowSourceAndEmptyIndex) {
  const Idx idx = {0, 0};
  const auto f = [&](Tape<double>& t, const std::vector<Var<double>>& v) { return gather_rows(t, v[0], idx); };
  expect_gradcheck(OpKind::GatherRows, f, {{random_matrix(1, 2, 12)}});
  const Idx none;
  const auto g = [&](Tape<double>& t, const std::vector<Var<double>>& v) { return gather_rows(t, v[0], none); };
  const GradcheckReport rep = expect_gradcheck(OpKind::GatherRows, g, {{random_matrix(3, 2, 13)}});
  EXPECT_EQ(rep.output.rows(), 0);
  EXPECT_TRUE(rep.gradients[0].isZero());
}

GRADCHECK_TEST(GatherRows, LargeEnoughForThreadsAndDeterministic) {
  Idx idx(900);
  for (std::size_t e = 0; e < idx.size(); ++e) idx[e] = static_cast<int32_t>((e * 37) % 50);
  const auto f = [&](Tape<double>& t, const std::vector<Var<double>>& v) { return gather_rows(t, v[0], idx); };
  const std::vector<GradcheckInput> in = {{random_matrix(50, 70, 14)}};
  expect_gradcheck(OpKind::GatherRows, f, in, large_options());
  expect_thread_count_invariant(f, in);
}

GRADCHECK_TEST(GatherRows, AColumnRange) {
  const Idx idx = {2, 0, 2, 1};
  const RowMat<double> x = random_matrix(3, 6, 16);
  const auto f = [&](Tape<double>& t, const std::vector<Var<double>>& v) { return gather_rows(t, v[0], idx, 1, 4); };
  const GradcheckReport rep = expect_gradcheck(OpKind::GatherRows, f, {{x}});
  ASSERT_EQ(rep.output.rows(), 4);
  ASSERT_EQ(rep.output.cols(), 3);
  for (int e = 0; e < 4; ++e)
    for (int c = 0; c < 3; ++c) EXPECT_EQ(rep.output(e, c), x(idx[e], 1 + c));
  // Columns outside the range get no gradient.
  EXPECT_TRUE(rep.gradients[0].col(0).isZero());
  EXPECT_TRUE(rep.gradients[0].rightCols(2).isZero());
}

GRADCHECK_TEST(GatherRows, AColumnRangeOverThreads) {
  Idx idx(900);
  for (std::size_t e = 0; e < idx.size(); ++e) idx[e] = static_cast<int32_t>((e * 37) % 50);
  const auto f = [&](Tape<double>& t, const std::vector<Var<double>>& v) { return gather_rows(t, v[0], idx, 20, 60); };
  const std::vector<GradcheckInput> in = {{random_matrix(50, 70, 17)}};
  expect_gradcheck(OpKind::GatherRows, f, in, large_options());
  expect_thread_count_invariant(f, in);
}

TEST(GatherRows, RejectsAColumnRangeOutsideX) {
  Tape<double> tape;
  const RowMat<double> x = random_matrix(3, 2, 18);
  Var<double> v = tape.leaf(x.data(), 3, 2);
  const Idx idx = {0, 1};
  EXPECT_THROW(gather_rows(tape, v, idx, 1, 3), CheckError);
  EXPECT_THROW(gather_rows(tape, v, idx, 2, 1), CheckError);
}

TEST(GatherRows, RejectsOutOfRangeIndex) {
  Tape<double> tape;
  const RowMat<double> x = random_matrix(3, 2, 15);
  Var<double> v = tape.leaf(x.data(), 3, 2);
  const Idx bad = {0, 3};
  EXPECT_THROW(gather_rows(tape, v, bad), CheckError);
}

// ---- scatter_add_rows -------------------------------------------------------------------

GRADCHECK_TEST(ScatterAddRows, DuplicatesAndEmptyTargets) {
  const Idx idx = {2, 0, 2, 2, 4};  // targets 1 and 3 get nothing
  const auto f = [&](Tape<double>& t, const std::vector<Var<double>>& v) {
    return scatter_add_rows(t, v[0], idx, 5);
  };
  const RowMat<double> x = random_matrix(5, 3, 21);
  const GradcheckReport rep = expect_gradcheck(OpKind::ScatterAddRows, f, {{x}});
  EXPECT_TRUE(rep.output.row(1).isZero());
  EXPECT_TRUE(rep.output.row(3).isZero());
  EXPECT_NEAR(rep.output(2, 1), x(0, 1) + x(2, 1) + x(3, 1), 1e-15);
}

GRADCHECK_TEST(ScatterAddRows, OneRowAndLargeDeterministic) {
  const Idx one = {0};
  const auto f1 = [&](Tape<double>& t, const std::vector<Var<double>>& v) { return scatter_add_rows(t, v[0], one, 1); };
  expect_gradcheck(OpKind::ScatterAddRows, f1, {{random_matrix(1, 1, 22)}});

  Idx idx(1000);
  for (std::size_t e = 0; e < idx.size(); ++e) idx[e] = static_cast<int32_t>((e * 13) % 40);
  const auto f = [&](Tape<double>& t, const std::vector<Var<double>>& v) { return scatter_add_rows(t, v[0], idx, 40); };
  const std::vector<GradcheckInput> in = {{random_matrix(1000, 96, 23)}};
  expect_gradcheck(OpKind::ScatterAddRows, f, in, large_options());
  expect_thread_count_invariant(f, in);
}

// ---- segment_sum ------------------------------------------------------------------------

GRADCHECK_TEST(SegmentSum, EmptySegmentsFirstMiddleLast) {
  const Idx offsets = {0, 0, 2, 2, 5, 5};  // segments 0, 2 and 4 are empty
  const auto f = [&](Tape<double>& t, const std::vector<Var<double>>& v) { return segment_sum(t, v[0], offsets); };
  const RowMat<double> x = random_matrix(5, 4, 31);
  const GradcheckReport rep = expect_gradcheck(OpKind::SegmentSum, f, {{x}});
  ASSERT_EQ(rep.output.rows(), 5);
  EXPECT_TRUE(rep.output.row(0).isZero());
  EXPECT_TRUE(rep.output.row(2).isZero());
  EXPECT_TRUE(rep.output.row(4).isZero());
  EXPECT_TRUE(rep.output.row(3).isApprox(x.row(2) + x.row(3) + x.row(4)));
}

GRADCHECK_TEST(SegmentSum, OneRowAndNoRows) {
  const Idx one = {0, 1};
  const auto f = [&](Tape<double>& t, const std::vector<Var<double>>& v) { return segment_sum(t, v[0], one); };
  expect_gradcheck(OpKind::SegmentSum, f, {{random_matrix(1, 3, 32)}});
  // Two empty segments over zero rows, then added to something with a gradient.
  const Idx empty = {0, 0, 0};
  Tape<double> tape;
  const RowMat<double> none(0, 3);
  Var<double> x = tape.leaf(none.data(), 0, 3);
  Var<double> y = segment_sum(tape, x, empty);
  EXPECT_EQ(y.rows, 2);
  EXPECT_TRUE(y.val().isZero());
}

TEST(SegmentSum, RejectsBadOffsets) {
  Tape<double> tape;
  const RowMat<double> x = random_matrix(3, 2, 33);
  Var<double> v = tape.leaf(x.data(), 3, 2);
  EXPECT_THROW(segment_sum(tape, v, Idx{0, 2}), CheckError);     // does not cover 3 rows
  EXPECT_THROW(segment_sum(tape, v, Idx{0, 2, 1, 3}), CheckError);  // decreasing
  EXPECT_THROW(segment_sum(tape, v, Idx{1, 3}), CheckError);     // does not start at 0
}

// ---- segment_softmax --------------------------------------------------------------------

GRADCHECK_TEST(SegmentSoftmax, SumsToOnePerSegmentWithEmptySegments) {
  const Idx offsets = {0, 3, 3, 4, 7};  // an empty segment and a single-row one
  const auto f = [&](Tape<double>& t, const std::vector<Var<double>>& v) {
    return segment_softmax(t, v[0], offsets);
  };
  const GradcheckReport rep = expect_gradcheck(OpKind::SegmentSoftmax, f, {{random_matrix(7, 2, 41, -3, 3)}});
  for (int h = 0; h < 2; ++h) {
    EXPECT_NEAR(rep.output.col(h).segment(0, 3).sum(), 1.0, 1e-14);
    EXPECT_EQ(rep.output(3, h), 1.0);  // a single row always gets all the weight
    EXPECT_NEAR(rep.output.col(h).segment(4, 3).sum(), 1.0, 1e-14);
  }
  // A single-row segment is constant: no gradient flows to its logit.
  EXPECT_EQ(rep.gradients[0](3, 0), 0.0);
}

GRADCHECK_TEST(SegmentSoftmax, LogitsOfPlusMinus80) {
  RowMat<double> z(4, 2);
  z << 80, -80, -80, 80, 79, -79.5, 0, 80;
  const Idx offsets = {0, 4};
  const auto f = [&](Tape<double>& t, const std::vector<Var<double>>& v) {
    return segment_softmax(t, v[0], offsets);
  };
  const GradcheckReport rep = expect_gradcheck(OpKind::SegmentSoftmax, f, {{z}});
  const double e1 = std::exp(-1.0);
  EXPECT_NEAR(rep.output(0, 0), 1 / (1 + e1), 1e-14);
  EXPECT_NEAR(rep.output(2, 0), e1 / (1 + e1), 1e-14);
  EXPECT_NEAR(rep.output(1, 1), 0.5, 1e-14);
  EXPECT_NEAR(rep.output(3, 1), 0.5, 1e-14);
  EXPECT_GT(rep.output(1, 0), 0.0);  // exp(-160) relative: tiny but representable in double

  // Far beyond exp's range: still finite and exact in float too.
  Tape<float> tape;
  const float big[] = {1e4f, -1e4f, 1e4f};
  Var<float> x = tape.leaf(big, 3, 1);
  Var<float> a = segment_softmax(tape, x, Idx{0, 3});
  EXPECT_FLOAT_EQ(a.value[0], 0.5f);
  EXPECT_FLOAT_EQ(a.value[1], 0.0f);
  EXPECT_FLOAT_EQ(a.value[2], 0.5f);
}

GRADCHECK_TEST(SegmentSoftmax, LargeDeterministic) {
  Idx offsets = {0};
  for (int k = 0; k < 300; ++k) offsets.push_back(offsets.back() + k % 9);
  const auto rows = offsets.back();
  const auto f = [&](Tape<double>& t, const std::vector<Var<double>>& v) {
    return segment_softmax(t, v[0], offsets);
  };
  const std::vector<GradcheckInput> in = {{random_matrix(rows, 8, 42, -5, 5)}};
  expect_gradcheck(OpKind::SegmentSoftmax, f, in, large_options());
  expect_thread_count_invariant(f, in);
}

// ---- concat_rows ------------------------------------------------------------------------

GRADCHECK_TEST(ConcatRows, TwoBlocksAndOneRowAndEmpty) {
  const auto f = [](Tape<double>& t, const std::vector<Var<double>>& v) { return concat_rows(t, v[0], v[1]); };
  const RowMat<double> a = random_matrix(3, 2, 51), b = random_matrix(1, 2, 52);
  const GradcheckReport rep = expect_gradcheck(OpKind::ConcatRows, f, {{a}, {b}});
  EXPECT_TRUE(rep.output.row(3).isApprox(b.row(0)));
  expect_gradcheck(OpKind::ConcatRows, f, {{RowMat<double>(0, 2)}, {b}});
  expect_gradcheck(OpKind::ConcatRows, f, {{a}, {b, false}});
}

}  // namespace layersnet::ad::testing

namespace layersnet::ad::testing {

TEST(SegmentSoftmax, MinusInfinityMasksAndAllMaskedGivesZeros) {
  Tape<double> tape;
  const double inf = std::numeric_limits<double>::infinity();
  const double z[] = {0.0, -inf, 1.0, -inf, -inf};
  Var<double> x = tape.leaf(z, 5, 1);
  Var<double> a = segment_softmax(tape, x, Idx{0, 3, 5});
  EXPECT_EQ(a.value[1], 0.0);
  EXPECT_NEAR(a.value[0] + a.value[2], 1.0, 1e-15);
  EXPECT_EQ(a.value[3], 0.0);
  EXPECT_EQ(a.value[4], 0.0);
  std::fill_n(a.grad, 5, 1.0);
  tape.backward_seeded();
  for (int k = 0; k < 5; ++k) EXPECT_TRUE(std::isfinite(x.grad[k])) << k;
}

TEST(Reshape, AliasesValuesAndGradients) {
  // (2, 6) relative states seen as (4, 3) 3-vectors, rotated, and the gradient arrives in
  // the (2, 6) tensor.
  const auto f = [](Tape<double>& t, const std::vector<Var<double>>& v) {
    return rotate3(t, v[0], reshape(v[1], 4, 3));
  };
  const RowMat<double> R = random_matrix(4, 9, 55), x = random_matrix(2, 6, 56);
  const GradcheckReport rep = expect_gradcheck(OpKind::Rotate3, f, {{R}, {x}});
  EXPECT_EQ(rep.gradients[1].rows(), 2);
  Tape<double> tape;
  Var<double> v = tape.leaf(x.data(), 2, 6);
  EXPECT_THROW(reshape(v, 5, 3), CheckError);
}

}  // namespace layersnet::ad::testing

namespace layersnet::ad::testing {

GRADCHECK_TEST(SegmentSoftmax, OneRowTensor) {
  const auto f = [](Tape<double>& t, const std::vector<Var<double>>& v) { return segment_softmax(t, v[0], Idx{0, 1}); };
  const GradcheckReport rep = expect_gradcheck(OpKind::SegmentSoftmax, f, {{random_matrix(1, 3, 43)}});
  EXPECT_TRUE(rep.output.isOnes());
  EXPECT_TRUE(rep.gradients[0].isZero());
}

}  // namespace layersnet::ad::testing
