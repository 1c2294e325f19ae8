// The loss terms on hand-countable configurations, their gradients, and the orthogonality floor.
#include "autodiff/gradcheck.h"
#include "losses/losses.h"
#include "model/params_layout.h"

#include <gtest/gtest.h>

#include <cmath>

namespace layersnet::losses {
namespace {

// Two triangles: inner garment at z = 0.1 (normal +z), outer garment partly below it; the
// body has one vertex under each (x, y) corner. Values are in the comments of each test.
struct Toy {
  LossInput<double> target;
  std::vector<double> pred;  // (6, 9)
  std::vector<double> patch; // (1, 9)
  // The predictions as tape leaves (read when called: a test may change pred or patch first).
  model::Predictions<double> leaves(ad::Tape<double>& tape) {
    return {tape.leaf(pred.data(), 6, 9), tape.leaf(patch.data(), 1, 9)};
  }
  Toy() {
    const double x[6][3] = {{0, 0, 0.1}, {1, 0, 0.1}, {0, 1, 0.1}, {0, 0, 0.1005}, {1, 0, 0.05}, {0, 1, 0.3}};
    pred.assign(6 * 9, 0.0);
    for (int v = 0; v < 6; ++v)
      for (int c = 0; c < 3; ++c) pred[9 * v + c] = x[v][c];
    patch.assign(9, 0.0);
    patch[2] = 0.2;
    target.target = {0, 0, 0.1, 1, 0, 0.1, 0, 1, 0.1, 0, 0, 0.2, 1, 0, 0.2, 0, 1, 0.2};  // vertex error only on outer z
    target.target_patch = {0, 0, 0.25};
    target.target_normals.assign(18, 0.0);
    for (int v = 0; v < 6; ++v) target.target_normals[3 * v + 2] = 1.0;
    target.faces = {0, 1, 2, 3, 4, 5};
    target.garment_offsets = {0, 3, 6};
    target.body_pos = {0, 0, 0, 1, 0, 0.0505, 0, 1, 0};
    target.body_normals = {0, 0, 1, 0, 0, 1, 0, 0, 1};
  }
};

ModelConfig no_ret() {
  ModelConfig c;
  c.rotation_equivalent = false;  // no RET maps: the orthogonality term is absent
  return c;
}

TEST(Losses, HandCountedValues) {
  Toy toy;
  ad::ParamStore<double> ps;
  ad::Tape<double> tape;
  model::Predictions<double> pred = toy.leaves(tape);
  LossConfig lc;
  const auto t = compute_losses(tape, ps, no_ret(), lc, toy.target, pred);
  // vertex: outer z errors 0.0995, 0.15, 0.1 over 6 vertices
  EXPECT_NEAR(t.vertex, (0.0995 * 0.0995 + 0.15 * 0.15 + 0.1 * 0.1) / 6, 1e-12);
  EXPECT_NEAR(t.patch, 0.05 * 0.05, 1e-12);
  // body: only outer v1 is within d_eps: d = 0.05 - 0.0505 = -0.0005 -> (-0.0015)^2, N_c = 1
  EXPECT_EQ(t.body_collisions, 1);
  EXPECT_NEAR(t.collision_body, 0.0015 * 0.0015, 1e-12);
  // layer: outer v0 d = 0.0005 -> (0.0005 - 0.001)^2; outer v1 d = -0.05 -> (-0.051)^2; N_c = 2
  EXPECT_EQ(t.layer_collisions, 2);
  EXPECT_NEAR(t.collision_layer, (0.0005 * 0.0005 + 0.051 * 0.051) / 2, 1e-12);
  // normal: inner normals are +z (0 error); the outer triangle's normal n gives 3·‖n − e_z‖².
  const double a[3] = {1, 0, 0.05 - 0.1005}, b[3] = {0, 1, 0.3 - 0.1005};
  double n[3] = {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
  const double len = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
  const double e = (n[0] / len) * (n[0] / len) + (n[1] / len) * (n[1] / len) + (n[2] / len - 1) * (n[2] / len - 1);
  EXPECT_NEAR(t.normal, 3 * e / 6, 1e-12);
  EXPECT_NEAR(t.total.scalar(), t.vertex + t.patch + t.normal + 1.3 * t.collision_body + 0.1 * t.collision_layer, 1e-12);
}

// loss.layer_mean_over = "outer": the same two colliding outer vertices, their sum over all three
// outer vertices; the body term keeps its mean over the colliding ones.
TEST(Losses, LayerTermOverEveryOuterVertex) {
  Toy toy;
  ad::ParamStore<double> ps;
  ad::Tape<double> tape;
  model::Predictions<double> pred = toy.leaves(tape);
  LossConfig lc;
  lc.layer_mean_over = "outer";
  const auto t = compute_losses(tape, ps, no_ret(), lc, toy.target, pred);
  EXPECT_EQ(t.layer_collisions, 2);
  EXPECT_NEAR(t.collision_layer, (0.0005 * 0.0005 + 0.051 * 0.051) / 3, 1e-12);
  EXPECT_NEAR(t.collision_body, 0.0015 * 0.0015, 1e-12);
}

// loss.relative_to_base: the vertex and patch terms are divided by the error of x − a, the
// prediction with a zero network output; the reported terms stay the raw errors.
TEST(Losses, RelativeToBaseDividesByTheZeroOutputError) {
  Toy toy;
  for (int v = 0; v < 6; ++v) toy.pred[9 * v + 8] = -0.1;  // base z = x_z + 0.1
  toy.patch[8] = 0.1;                                      // patch base z = 0.1
  ad::ParamStore<double> ps;
  ad::Tape<double> tape;
  model::Predictions<double> pred = toy.leaves(tape);
  LossConfig lc;
  lc.normal = lc.collision_body = lc.collision_layer = 0;
  lc.relative_to_base = true;
  const auto t = compute_losses(tape, ps, no_ret(), lc, toy.target, pred);
  EXPECT_NEAR(t.vertex, (0.0995 * 0.0995 + 0.15 * 0.15 + 0.1 * 0.1) / 6, 1e-12);
  // base z errors: inner 0.1 each, outer 0.0005, -0.05, 0.2; over 6 vertices x 3 coordinates
  const double base_vertex = (3 * 0.01 + 0.0005 * 0.0005 + 0.05 * 0.05 + 0.2 * 0.2) / 18;
  const double base_patch = 0.15 * 0.15 / 3;
  EXPECT_NEAR(t.total.scalar(), t.vertex / base_vertex + t.patch / base_patch, 1e-9);
  // A base on the target is floored at (1 mm)² = 1e-4 units² per coordinate, not divided by 0.
  for (int v = 0; v < 6; ++v)
    for (int c = 0; c < 3; ++c) toy.pred[9 * v + 6 + c] = toy.pred[9 * v + c] - toy.target.target[3 * v + c];
  model::Predictions<double> on_target{tape.leaf(toy.pred.data(), 6, 9), tape.leaf(toy.patch.data(), 1, 9)};
  const auto floored = compute_losses(tape, ps, no_ret(), lc, toy.target, on_target);
  EXPECT_NEAR(floored.total.scalar(), floored.vertex / 1e-4 + floored.patch / base_patch, 1e-6);
}

TEST(Losses, GradientsOfEveryTermMatchFiniteDifferences) {
  Toy toy;
  ad::ParamStore<double> ps;
  const auto f = [&](ad::Tape<double>& tape, const std::vector<ad::Var<double>>& in) {
    return compute_losses(tape, ps, no_ret(), LossConfig{}, toy.target, model::Predictions<double>{in[0], in[1]}).total;
  };
  ad::GradcheckInput v{Eigen::Map<ad::RowMat<double>>(toy.pred.data(), 6, 9)};
  ad::GradcheckInput p{Eigen::Map<ad::RowMat<double>>(toy.patch.data(), 1, 9)};
  const auto report = ad::gradcheck(f, {v, p});
  EXPECT_TRUE(report.ok) << report.failures;
}

TEST(Losses, EdgeStrainHandCountedAndGradcheck) {
  Toy toy;
  set_target_edges(toy.target);
  ASSERT_EQ(toy.target.edges.size(), 12u);  // two triangles, three edges each
  LossConfig lc;
  lc.vertex = lc.patch = lc.normal = lc.collision_body = lc.collision_layer = 0;
  lc.edge_strain = 2.0;
  ad::ParamStore<double> ps;
  ad::Tape<double> tape;
  model::Predictions<double> pred = toy.leaves(tape);
  const auto t = compute_losses(tape, ps, no_ret(), lc, toy.target, pred);
  // Inner triangle: exact lengths (0 strain). Outer edges: ground truth 1, 1, sqrt(2) at z = 0.2;
  // predicted (0,0,.1005)-(1,0,.05), (0,0,.1005)-(0,1,.3), (1,0,.05)-(0,1,.3).
  const double l01 = std::sqrt(1 + 0.0505 * 0.0505), l02 = std::sqrt(1 + 0.1995 * 0.1995),
               l12 = std::sqrt(2 + 0.25 * 0.25);
  const double expected =
      ((l01 - 1) * (l01 - 1) + (l02 - 1) * (l02 - 1) + (l12 / std::sqrt(2.0) - 1) * (l12 / std::sqrt(2.0) - 1)) / 6;
  EXPECT_NEAR(t.edge_strain, expected, 1e-12);
  EXPECT_NEAR(t.total.scalar(), 2.0 * expected, 1e-12);
  const auto f = [&](ad::Tape<double>& tp, const std::vector<ad::Var<double>>& in) {
    return compute_losses(tp, ps, no_ret(), lc, toy.target, model::Predictions<double>{in[0], in[1]}).total;
  };
  ad::GradcheckInput v{Eigen::Map<ad::RowMat<double>>(toy.pred.data(), 6, 9)};
  ad::GradcheckInput p{Eigen::Map<ad::RowMat<double>>(toy.patch.data(), 1, 9)};
  const auto report = ad::gradcheck(f, {v, p});
  EXPECT_TRUE(report.ok) << report.failures;
}

// With orthonormal columns, ‖W Wᵀ − I_d‖² = d − c and ‖Wᵀ W − I_c‖² = 0 for W (d, c): official
// sizes give 16·(16 − 3) + (128 − 3) = 333 at initialisation (the official penalty's floor); our default
// decoder map with k = 8 channels (c = 24) gives 16·13 + (128 − 24) = 312.
class OrthogonalityFloor : public ::testing::TestWithParam<std::pair<int, double>> {};
INSTANTIATE_TEST_SUITE_P(DecoderChannels, OrthogonalityFloor,
                         ::testing::Values(std::make_pair(1, 333.0), std::make_pair(8, 312.0)));
TEST_P(OrthogonalityFloor, AtInitialisation) {
  ModelConfig c;
  c.decoder_ret_channels = GetParam().first;
  ad::ParamStore<double> ps;
  model::register_params(ps, c);
  model::init_params(ps, c, 1);
  Toy toy;
  LossConfig lc;
  lc.vertex = lc.patch = lc.normal = lc.collision_body = lc.collision_layer = 0;
  ad::Tape<double> tape;
  model::Predictions<double> pred{tape.constant(toy.pred.data(), 6, 9), tape.constant(toy.patch.data(), 1, 9)};
  const auto t = compute_losses(tape, ps, c, lc, toy.target, pred);
  EXPECT_NEAR(t.orthogonality, GetParam().second, 1e-9);
  EXPECT_NEAR(t.total.scalar(), GetParam().second, 1e-9);
}

}  // namespace
}  // namespace layersnet::losses
