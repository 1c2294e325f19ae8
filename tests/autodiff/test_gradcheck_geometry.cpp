// Gradient checks of the geometry ops (autodiff/ops_geometry.h): zero rows, zero-area
// triangles, rotations of normals parallel to each axis.
#include "autodiff/ops_graph.h"
#include "gradcheck_registry.h"

#include <Eigen/Dense>

#include <array>
#include <cmath>
#include <vector>

namespace layersnet::ad::testing {

namespace {

// Unit normals: the six axis directions, near-axis ones (components below and just above the
// official 1e-7 threshold) and random directions.
RowMat<double> test_normals() {
  std::vector<std::array<double, 3>> n = {{1, 0, 0}, {-1, 0, 0}, {0, 1, 0},    {0, -1, 0},   {0, 0, 1},
                                          {0, 0, -1}, {1, 1e-8, 0}, {1, 2e-7, -2e-7}, {3e-7, 1, 0}, {-2e-7, 0, -1},
                                          {1, 1e-4, 0}, {0.6, 0.8, 0}};
  const RowMat<double> r = random_matrix(8, 3, 90);
  for (int k = 0; k < r.rows(); ++k) n.push_back({r(k, 0), r(k, 1), r(k, 2)});
  RowMat<double> out(static_cast<int64_t>(n.size()), 3);
  for (std::size_t k = 0; k < n.size(); ++k) {
    const double len = std::sqrt(n[k][0] * n[k][0] + n[k][1] * n[k][1] + n[k][2] * n[k][2]);
    for (int c = 0; c < 3; ++c) out(static_cast<int64_t>(k), c) = n[k][static_cast<std::size_t>(c)] / len;
  }
  return out;
}

// A world -> local frame of each unit normal n as rows [x; y; n] of 9 numbers (R n = e_z): x from
// the axis least parallel to n, orthogonalised twice. The model's own frame rule
// (model::normal_frame) is tested with the model.
RowMat<double> frames(const RowMat<double>& normals) {
  RowMat<double> R(normals.rows(), 9);
  for (int64_t k = 0; k < normals.rows(); ++k) {
    const Eigen::Vector3d n = normals.row(k).transpose();
    Eigen::Index axis;
    n.cwiseAbs().minCoeff(&axis);
    Eigen::Vector3d x = Eigen::Vector3d::Unit(axis);
    for (int pass = 0; pass < 2; ++pass) x = (x - x.dot(n) * n).normalized();
    const Eigen::Vector3d y = n.cross(x);
    for (int c = 0; c < 3; ++c) R(k, c) = x[c], R(k, 3 + c) = y[c], R(k, 6 + c) = n[c];
  }
  return R;
}

}  // namespace

// ---- row_norm / row_normalize -----------------------------------------------------------

GRADCHECK_TEST(RowNorm, RandomRowsAndAZeroRow) {
  RowMat<double> x = random_matrix(4, 5, 61);
  x.row(2).setZero();
  const auto f = [](Tape<double>& t, const std::vector<Var<double>>& v) { return row_norm(t, v[0]); };
  const GradcheckReport rep = expect_gradcheck(OpKind::RowNorm, f, {{x}});
  EXPECT_EQ(rep.output(2, 0), 0.0);
  EXPECT_NEAR(rep.output(1, 0), x.row(1).norm(), 1e-15);
  // At the zero row the central difference is (eps - eps) / 2eps = 0: the subgradient we return.
  EXPECT_TRUE(rep.gradients[0].row(2).isZero());
}

GRADCHECK_TEST(RowNorm, OneRowOneColumn) {
  const auto f = [](Tape<double>& t, const std::vector<Var<double>>& v) { return row_norm(t, v[0]); };
  RowMat<double> x(1, 1);
  x << -0.3;
  const GradcheckReport rep = expect_gradcheck(OpKind::RowNorm, f, {{x}});
  EXPECT_DOUBLE_EQ(rep.output(0, 0), 0.3);
}

GRADCHECK_TEST(RowNormalize, UnitRowsAndGradients) {
  const auto f = [](Tape<double>& t, const std::vector<Var<double>>& v) { return row_normalize(t, v[0]); };
  const GradcheckReport rep = expect_gradcheck(OpKind::RowNormalize, f, {{random_matrix(6, 3, 62)}});
  for (int n = 0; n < 6; ++n) EXPECT_NEAR(rep.output.row(n).norm(), 1.0, 1e-14);
}

GRADCHECK_TEST(RowNormalize, ZeroRowUsesTheEpsConvention) {
  // Below eps the op is x / eps: continuous at zero, gradient g / eps. With eps = 1e-3 the
  // finite differences (step 1e-6) stay inside that region, so the convention is checked.
  RowMat<double> x = random_matrix(3, 3, 63);
  x.row(0).setZero();
  x.row(1) *= 1e-5;  // short but non-zero: also below eps
  const auto f = [](Tape<double>& t, const std::vector<Var<double>>& v) { return row_normalize(t, v[0], 1e-3); };
  const GradcheckReport rep = expect_gradcheck(OpKind::RowNormalize, f, {{x}});
  EXPECT_TRUE(rep.output.row(0).isZero());
  EXPECT_TRUE(rep.output.row(1).isApprox(x.row(1) / 1e-3));

  // The default eps (1e-12) at an exactly zero row: zero output, finite gradient.
  const auto g = [](Tape<double>& t, const std::vector<Var<double>>& v) { return row_normalize(t, v[0]); };
  GradcheckOptions opt;
  opt.max_coords = 0;
  const RowMat<double> zero = RowMat<double>::Zero(1, 3);
  const GradcheckReport z = gradcheck(g, {{zero}}, opt);
  EXPECT_TRUE(z.finite);
  EXPECT_TRUE(z.output.isZero());
}

// ---- cross3 -----------------------------------------------------------------------------

GRADCHECK_TEST(Cross3, RandomAndCounterClockwiseFaceNormal) {
  const auto f = [](Tape<double>& t, const std::vector<Var<double>>& v) { return cross3(t, v[0], v[1]); };
  expect_gradcheck(OpKind::Cross3, f, {{random_matrix(5, 3, 64)}, {random_matrix(5, 3, 65)}});
  expect_gradcheck(OpKind::Cross3, f, {{random_matrix(1, 3, 66)}, {random_matrix(1, 3, 67), false}});

  // Triangle v0=(0,0,0), v1=(1,0,0), v2=(0,1,0), counter-clockwise seen from +z:
  // official normal (v2 - v1) x (v0 - v1) = +z.
  RowMat<double> e21(1, 3), e01(1, 3);
  e21 << -1, 1, 0;
  e01 << -1, 0, 0;
  const GradcheckReport rep = gradcheck(f, {{e21}, {e01}});
  EXPECT_TRUE(rep.output.isApprox((RowMat<double>(1, 3) << 0, 0, 1).finished()));
}

GRADCHECK_TEST(Cross3, ZeroAreaTrianglesThroughRowNormalize) {
  // Face normals of triangles given by vertices (F, 9): collinear and coincident vertices
  // give a zero cross product; normalize must keep outputs and gradients finite.
  RowMat<double> tri = random_matrix(4, 9, 68);
  tri.block(1, 6, 1, 3) = 2 * tri.block(1, 3, 1, 3) - tri.block(1, 0, 1, 3);  // v2 = v1 + (v1 - v0): collinear
  tri.block(2, 3, 1, 3) = tri.block(2, 0, 1, 3);                              // v1 = v0
  tri.block(3, 3, 1, 6) << tri.block(3, 0, 1, 3), tri.block(3, 0, 1, 3);      // all three equal
  const auto f = [](Tape<double>& t, const std::vector<Var<double>>& v) {
    // v[0] = v2 - v1, v[1] = v0 - v1 per face
    return row_normalize(t, cross3(t, v[0], v[1]));
  };
  RowMat<double> a(4, 3), b(4, 3);
  for (int k = 0; k < 4; ++k) {
    a.row(k) = tri.block(k, 6, 1, 3) - tri.block(k, 3, 1, 3);
    b.row(k) = tri.block(k, 0, 1, 3) - tri.block(k, 3, 1, 3);
  }
  GradcheckOptions opt;
  opt.max_coords = 0;  // finite differences across the kink at zero are not meaningful
  const GradcheckReport rep = gradcheck(f, {{a}, {b}}, opt);
  EXPECT_TRUE(rep.finite) << rep.failures;
  EXPECT_TRUE(rep.ops_seen.count(OpKind::Cross3));
  EXPECT_NEAR(rep.output.row(0).norm(), 1.0, 1e-12);
  for (int k = 1; k < 4; ++k) EXPECT_LT(rep.output.row(k).norm(), 1e-3) << "face " << k;
  // The non-degenerate face still passes a full check.
  expect_gradcheck(OpKind::Cross3, f, {{a.topRows(1)}, {b.topRows(1)}});
}

// ---- rotate3 ----------------------------------------------------------------------------

GRADCHECK_TEST(Rotate3, BothDirections) {
  for (bool transpose : {false, true}) {
    const auto f = [transpose](Tape<double>& t, const std::vector<Var<double>>& v) {
      return rotate3(t, v[0], v[1], transpose);
    };
    const RowMat<double> R = random_matrix(4, 9, 70), x = random_matrix(4, 3, 71);
    const GradcheckReport rep = expect_gradcheck(OpKind::Rotate3, f, {{R}, {x}});
    Eigen::Matrix3d m;
    m << R(2, 0), R(2, 1), R(2, 2), R(2, 3), R(2, 4), R(2, 5), R(2, 6), R(2, 7), R(2, 8);
    const Eigen::Vector3d want = (transpose ? Eigen::Matrix3d(m.transpose()) : m) * x.row(2).transpose();
    EXPECT_TRUE(rep.output.row(2).transpose().isApprox(want));
  }
}

GRADCHECK_TEST(Rotate3, FramesOfAxisNormalsMapNormalsToEz) {
  const RowMat<double> n = test_normals();
  const RowMat<double> R = frames(n);
  const auto f = [](Tape<double>& t, const std::vector<Var<double>>& v) { return rotate3(t, v[0], v[1]); };
  const GradcheckReport rep = expect_gradcheck(OpKind::Rotate3, f, {{R}, {n}});
  for (int64_t k = 0; k < n.rows(); ++k) {
    EXPECT_NEAR(rep.output(k, 0), 0.0, 1e-12) << "normal " << k;
    EXPECT_NEAR(rep.output(k, 1), 0.0, 1e-12) << "normal " << k;
    EXPECT_NEAR(rep.output(k, 2), 1.0, 1e-12) << "normal " << k;
  }
  // And back: R^T e_z = n.
  RowMat<double> ez = RowMat<double>::Zero(n.rows(), 3);
  ez.col(2).setOnes();
  const auto b = [](Tape<double>& t, const std::vector<Var<double>>& v) { return rotate3(t, v[0], v[1], true); };
  const GradcheckReport back = expect_gradcheck(OpKind::Rotate3, b, {{R}, {ez}});
  EXPECT_TRUE(back.output.isApprox(n, 1e-12));
}

// ---- rot_map_apply ----------------------------------------------------------------------

GRADCHECK_TEST(RotMapApply, MatchesExplicitWRWtBothDirections) {
  const int d = 16, n_rows = 5;
  for (bool transpose : {false, true}) {
    const auto f = [transpose](Tape<double>& t, const std::vector<Var<double>>& v) {
      return rot_map_apply(t, v[0], v[1], v[2], transpose);
    };
    const RowMat<double> W = random_matrix(d, 3, 80), R = random_matrix(n_rows, 9, 81), x = random_matrix(n_rows, d, 82);
    const GradcheckReport rep = expect_gradcheck(OpKind::RotMapApply, f, {{W}, {R}, {x}});
    for (int n = 0; n < n_rows; ++n) {
      Eigen::Matrix3d m;
      for (int c = 0; c < 9; ++c) m(c / 3, c % 3) = R(n, c);
      if (transpose) m.transposeInPlace();
      const Eigen::MatrixXd phi = W * m * W.transpose();  // (d, d), only for the check
      EXPECT_TRUE(rep.output.row(n).transpose().isApprox(phi * x.row(n).transpose(), 1e-12));
    }
  }
}

GRADCHECK_TEST(RotMapApply, OneRowAndAxisFramesWithOrthonormalW) {
  const auto f = [](Tape<double>& t, const std::vector<Var<double>>& v) { return rot_map_apply(t, v[0], v[1], v[2]); };
  expect_gradcheck(OpKind::RotMapApply, f, {{random_matrix(4, 3, 83)}, {random_matrix(1, 9, 84)}, {random_matrix(1, 4, 85)}});

  // With W of orthonormal columns and proper rotations, phi(R)^T phi(R) v = W W^T v: the map
  // back (transpose) undoes the map forward on the 3-D subspace (eq. 9 on that subspace).
  const RowMat<double> n = test_normals();
  const RowMat<double> R = frames(n);
  const Eigen::MatrixXd q = Eigen::HouseholderQR<Eigen::MatrixXd>(random_matrix(8, 3, 86)).householderQ();
  const RowMat<double> W = q.leftCols(3);
  const RowMat<double> x = random_matrix(n.rows(), 8, 87);
  const auto there_and_back = [](Tape<double>& t, const std::vector<Var<double>>& v) {
    return rot_map_apply(t, v[0], v[1], rot_map_apply(t, v[0], v[1], v[2]), true);
  };
  const GradcheckReport rep = expect_gradcheck(OpKind::RotMapApply, there_and_back, {{W, false}, {R, false}, {x}});
  const RowMat<double> projected = x * W * W.transpose();
  EXPECT_TRUE(rep.output.isApprox(projected, 1e-12));
}

}  // namespace layersnet::ad::testing

namespace layersnet::ad::testing {

GRADCHECK_TEST(Rotate3, OneRowEachDirectionAndConstantRotation) {
  for (bool transpose : {false, true}) {
    const auto f = [transpose](Tape<double>& t, const std::vector<Var<double>>& v) {
      return rotate3(t, v[0], v[1], transpose);
    };
    expect_gradcheck(OpKind::Rotate3, f, {{random_matrix(1, 9, 72)}, {random_matrix(1, 3, 73)}});
    expect_gradcheck(OpKind::Rotate3, f, {{random_matrix(1, 9, 74), false}, {random_matrix(1, 3, 75)}});
  }
}

GRADCHECK_TEST(RowNormalize, OneRowOneColumn) {
  const auto f = [](Tape<double>& t, const std::vector<Var<double>>& v) { return row_normalize(t, v[0]); };
  RowMat<double> x(1, 1);
  x << -2.5;
  const GradcheckReport rep = expect_gradcheck(OpKind::RowNormalize, f, {{x}});
  EXPECT_EQ(rep.output(0, 0), -1.0);
}

}  // namespace layersnet::ad::testing
