// Whole-model gradient check, every parameter trained, translation
// invariance, and absent parts (wind, second garment) skip exactly their work. Inputs come
// from the production road in float (model_test_util.h); the double checks cast them.
#include "losses/losses.h"
#include "autodiff/ops_dense.h"
#include "model/layersnet.h"
#include "model/params_layout.h"
#include "model_test_util.h"

#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <iostream>
#include <random>

namespace layersnet::model {
namespace {

template <class T>
struct Sample {
  ModelInput<T> input;
  losses::LossInput<T> target;
};

template <class T>
Sample<T> make_sample(const dataset::SyntheticOptions& o, const ModelConfig& c) {
  const auto w = testing::window(dataset::make_synthetic_sequence(o), c);
  return {cast_input<T>(w.input), losses::cast_loss_input<T>(w.target)};
}

template <class T>
double loss_value(ad::ParamStore<T>& ps, const ModelConfig& c, const LossConfig& lc, const Sample<T>& s) {
  ad::Tape<T> tape;
  ad::NoRecord<T> off(tape);
  const auto pred = forward(tape, ps, c, s.input);
  return static_cast<double>(losses::compute_losses(tape, ps, c, lc, s.target, pred).total.scalar());
}

// JAX check_grads style: <∇L, d> against the central difference along one random direction.
// `after_init` may move parameters that start at zero, so that the paths behind them count.
// The tiny scene's garments touch the body and each other, so the collision terms count too,
// unless `collisions` is false (the physics step's prediction pushes the cloth out of the body).
void directional_check(const ModelConfig& c, const std::function<void(ad::ParamStore<double>&)>& after_init = {},
                       bool collisions = true) {
  const auto s = make_sample<double>(testing::tiny_scene(), c);
  ad::ParamStore<double> ps;
  register_params(ps, c);
  init_params(ps, c, 3);
  if (after_init) after_init(ps);
  LossConfig lc;
  lc.collision_eps = 0.05;  // more active collision terms in the tiny scene
  ad::Tape<double> tape;
  const auto pred = forward(tape, ps, c, s.input);
  const auto terms = losses::compute_losses(tape, ps, c, lc, s.target, pred);
  ps.zero_grads();
  tape.backward(terms.total);
  std::mt19937_64 rng(11);
  std::normal_distribution<double> normal(0, 1);
  std::vector<double> dir(ps.values().size());
  double analytic = 0;
  for (std::size_t i = 0; i < dir.size(); ++i) dir[i] = normal(rng), analytic += dir[i] * ps.grads()[i];
  const std::vector<double> x0(ps.values().begin(), ps.values().end());
  const double eps = 1e-7;  // 1e-6 crossed a ReLU or contact kink in the TIE variant (0.5 % off; 1e-7 agrees)
  auto at = [&](double t) {
    for (std::size_t i = 0; i < dir.size(); ++i) ps.values()[i] = x0[i] + t * dir[i];
    return loss_value(ps, c, lc, s);
  };
  const double numeric = (at(eps) - at(-eps)) / (2 * eps);
  std::cout << "directional: analytic " << analytic << " numeric " << numeric << "\n";
  EXPECT_GT(std::abs(numeric), 1e-6);
  EXPECT_NEAR(analytic, numeric, 1e-10 + 1e-4 * std::abs(numeric))
      << "attention " << c.attention << ", RET " << c.rotation_equivalent;
  if (collisions) {
    EXPECT_GT(terms.body_collisions, 0);
    EXPECT_GT(terms.layer_collisions, 0);
  }
}

TEST(ModelGradcheck, WholeModelRiaRet) { directional_check(testing::tiny_config()); }

TEST(ModelGradcheck, WholeModelTie) {
  auto c = testing::tiny_config();
  c.attention = "tie";
  directional_check(c);
}

TEST(ModelGradcheck, WholeModelVanillaNoRet) {
  auto c = testing::tiny_config();
  c.rotation_equivalent = false;
  directional_check(c);
}

TEST(ModelGradcheck, WholeModelExactOrthogonality) {
  auto c = testing::tiny_config();
  c.orthogonality = "exact";
  directional_check(c);
}

TEST(ModelGradcheck, WholeModelBodyBaseSmoothedOutput) {
  auto c = testing::tiny_config();
  c.velocity_base = "body";
  c.output_smoothing = 2;
  directional_check(c);
}

// The base inputs (patch mean, per vertex): a zero weight gives the model without it (its
// initial state); with that weight and the decoder's output layer drawn, the prediction moves and
// the gradient holds.
void check_base_input(bool ModelConfig::*flag, const std::string& weight) {
  auto c = testing::tiny_config();
  c.velocity_base = "body";
  auto with = c;
  with.*flag = true;
  const auto s = make_sample<double>(testing::tiny_scene(), with);
  ad::ParamStore<double> plain, based;
  register_params(plain, c);
  init_params(plain, c, 3);
  register_params(based, with);
  init_params(based, with, 3);
  const auto draw = testing::draw_normal;
  for (auto* ps : {&plain, &based}) draw(*ps, "decoder.proj.2.weight", 5);
  ad::Tape<double> tape;
  const Eigen::MatrixXd a = forward(tape, plain, c, s.input).vertex.val();
  const Eigen::MatrixXd b = forward(tape, based, with, s.input).vertex.val();
  // Zero columns in the decoder's first layer change its summation order only.
  EXPECT_LE((a - b).cwiseAbs().maxCoeff(), 1e-12) << weight;
  draw(based, weight, 6);
  const Eigen::MatrixXd moved = forward(tape, based, with, s.input).vertex.val();
  EXPECT_GT((moved - a).cwiseAbs().maxCoeff(), 1e-10) << weight;  // the tiny scene's carry is small: 5e-8 units
  directional_check(with, [&](ad::ParamStore<double>& ps) {
    draw(ps, weight, 6);
    draw(ps, "decoder.proj.2.weight", 5);
  });
}

TEST(ModelGradcheck, WholeModelBodyBasePatchBaseInput) { check_base_input(&ModelConfig::patch_base_input, "embed.base.weight"); }

TEST(ModelGradcheck, WholeModelBodyBaseVertexBaseInput) {
  check_base_input(&ModelConfig::vertex_base_input, "decoder.base.weight");
}

// The correction solved through the physics step's system: a zero output is the step itself, as
// with the added correction; a drawn output moves the cloth less than the same correction added
// (the springs resist it), and the gradient through the solve holds.
TEST(ModelGradcheck, WholeModelPhysicsBaseSolvedCorrection) {
  auto added = testing::tiny_config();
  added.velocity_base = "physics";
  auto solved = added;
  solved.physics_step_correction = "solved";
  const auto sa = make_sample<double>(testing::tiny_scene(), added);
  const auto ss = make_sample<double>(testing::tiny_scene(), solved);
  ASSERT_TRUE(sa.input.system_offsets.empty());
  ASSERT_EQ(static_cast<int64_t>(ss.input.system_offsets.size()), ss.input.N + 1);
  ad::ParamStore<double> ps;
  register_params(ps, solved);
  init_params(ps, solved, 3);
  auto predict = [&](const ModelConfig& cfg, const ModelInput<double>& in) {
    ad::Tape<double> tape;
    return Eigen::MatrixXd(forward(tape, ps, cfg, in).vertex.val());
  };
  EXPECT_EQ((predict(added, sa.input) - predict(solved, ss.input)).cwiseAbs().maxCoeff(), 0.0);
  testing::draw_normal(ps, "decoder.proj.2.weight", 5);
  const Eigen::MatrixXd a_added = predict(added, sa.input).rightCols(3), a_solved = predict(solved, ss.input).rightCols(3);
  EXPECT_GT(a_added.norm(), 1e-6);
  EXPECT_GT(a_solved.norm(), 0.0);
  EXPECT_LT(a_solved.norm(), a_added.norm());
  directional_check(
      solved, [&](ad::ParamStore<double>& p) { testing::draw_normal(p, "decoder.proj.2.weight", 5); }, false);
}

// The wind force input: zero weights give the model without it (its initial state); drawn, they
// move the prediction and the gradient holds; a calm scene runs exactly the model without it.
TEST(ModelGradcheck, WholeModelWindForceInput) {
  auto c = testing::tiny_config();
  c.velocity_base = "body";
  auto with = c;
  with.wind_force_input = true;
  const auto s = make_sample<double>(testing::tiny_scene(), with);
  ASSERT_FALSE(s.input.wind_force.empty());
  ad::ParamStore<double> plain, winded;
  register_params(plain, c);
  init_params(plain, c, 3);
  register_params(winded, with);
  init_params(winded, with, 3);
  const auto draw = testing::draw_normal;
  for (auto* ps : {&plain, &winded}) draw(*ps, "decoder.proj.2.weight", 5);
  auto predict = [&](ad::ParamStore<double>& ps, const ModelConfig& cfg, const ModelInput<double>& in) {
    ad::Tape<double> tape;
    const Eigen::MatrixXd out = forward(tape, ps, cfg, in).vertex.val();
    return std::make_pair(out, tape.nodes().size());
  };
  const Eigen::MatrixXd a = predict(plain, c, s.input).first;
  // Zero columns join the first layer's products, which may then sum in another order: 3e-18.
  EXPECT_LT((a - predict(winded, with, s.input).first).cwiseAbs().maxCoeff(), 1e-14);
  draw(winded, "decoder.wind.weight", 6);
  const Eigen::MatrixXd decoder_moved = predict(winded, with, s.input).first;
  EXPECT_GT((decoder_moved - a).cwiseAbs().maxCoeff(), 1e-6);
  draw(winded, "embed.wind_force.weight", 7);
  EXPECT_GT((predict(winded, with, s.input).first - decoder_moved).cwiseAbs().maxCoeff(), 1e-8);
  // Calm: the same tape and bits as the model without the input.
  const auto calm = make_sample<double>(testing::tiny_scene(false), with);
  EXPECT_TRUE(calm.input.wind_force.empty());
  const auto [calm_plain, calm_nodes_plain] = predict(plain, c, calm.input);
  const auto [calm_winded, calm_nodes_winded] = predict(winded, with, calm.input);
  EXPECT_EQ(calm_nodes_plain, calm_nodes_winded);
  EXPECT_EQ((calm_plain - calm_winded).cwiseAbs().maxCoeff(), 0.0);
  directional_check(with, [&](ad::ParamStore<double>& ps) {
    draw(ps, "decoder.wind.weight", 6);
    draw(ps, "embed.wind_force.weight", 7);
    draw(ps, "decoder.proj.2.weight", 5);
  });
}

// "exact": the effective W has orthonormal columns for any raw parameter, equals the raw
// parameter at initialisation, and the loss has no orthogonality term.
TEST(ModelOrthogonality, ExactParametrisationHoldsForAnyParameter) {
  auto c = testing::tiny_config();
  c.orthogonality = "exact";
  ad::ParamStore<double> ps;
  register_params(ps, c);
  init_params(ps, c, 12);
  std::mt19937_64 rng(3);
  std::normal_distribution<double> normal(0, 1);
  for (const auto& name : rotation_map_names(c)) {
    ad::Tape<double> tape;
    const auto W0 = rotation_map(tape, ps, c, name);
    EXPECT_LT((W0.val() - ps.var(name).val()).norm(), 1e-12) << name;
    for (auto& x : ps.value(ps.index_of(name))) x += 0.7 * normal(rng);
    const auto W = rotation_map(tape, ps, c, name);
    Eigen::MatrixXd WtW = W.val().transpose() * W.val();
    EXPECT_LT((WtW - Eigen::MatrixXd::Identity(WtW.rows(), WtW.cols())).norm(), 1e-12) << name;
  }
  const auto s = make_sample<double>(testing::tiny_scene(), c);
  ad::Tape<double> tape;
  const auto pred = forward(tape, ps, c, s.input);
  const auto t = losses::compute_losses(tape, ps, c, LossConfig{}, s.target, pred);
  EXPECT_EQ(t.orthogonality, 0.0);
}

// orthogonality_floor is the penalty the loss computes at the orthonormal initialisation
// (official sizes 333, our default k = 8: 312, tiny sizes: 1 layer x 1 group x (head dim 8 - 3) +
// (d 16 - 3k 12) = 9), and 0 where the loss has no penalty.
TEST(ModelOrthogonality, FloorEqualsThePenaltyAtTheOrthonormalInitialisation) {
  ModelConfig official;
  official.decoder_ret_channels = 1;
  ModelConfig vanilla = testing::tiny_config();
  vanilla.rotation_equivalent = false;
  ModelConfig exact = testing::tiny_config();
  exact.orthogonality = "exact";
  const std::pair<ModelConfig, double> cases[] = {
      {official, 333}, {ModelConfig{}, 312}, {testing::tiny_config(), 1 * 1 * (8 - 3) + (16 - 12)}, {vanilla, 0}, {exact, 0}};
  const LossConfig lc;  // every term on; the penalty's own value is logged apart from them
  for (const auto& [c, expected] : cases) {
    SCOPED_TRACE("width " + std::to_string(c.width) + " k " + std::to_string(c.decoder_ret_channels) + " " +
                 c.orthogonality + (c.rotation_equivalent ? "" : " vanilla"));
    EXPECT_DOUBLE_EQ(orthogonality_floor(c), expected);
    ad::ParamStore<double> ps;
    register_params(ps, c);
    init_params(ps, c, 5);
    const auto s = make_sample<double>(testing::tiny_scene(), c);
    ad::Tape<double> tape;
    const auto pred = forward(tape, ps, c, s.input);
    const auto t = losses::compute_losses(tape, ps, c, lc, s.target, pred);
    EXPECT_NEAR(t.orthogonality, orthogonality_floor(c), 1e-9);
  }
}

// Every registered tensor gets a non-zero gradient from one realistic sample (two garments,
// wind, body contact), in float as in training.
TEST(ModelGradients, EveryParameterGetsAGradient) {
  for (const bool ret : {true, false}) {
    auto c = testing::tiny_config();
    c.rotation_equivalent = ret;
    const auto s = make_sample<float>(testing::tiny_scene(), c);
    ad::ParamStore<float> ps;
    register_params(ps, c);
    init_params(ps, c, 5);
    ad::Tape<float> tape;
    const auto pred = forward(tape, ps, c, s.input);
    const auto terms = losses::compute_losses(tape, ps, c, LossConfig{}, s.target, pred);
    ps.zero_grads();
    tape.backward(terms.total);
    for (const auto& e : ps.entries()) {
      double g = 0;
      for (int64_t k = 0; k < e.size(); ++k) g += std::abs(ps.grads()[e.offset + k]);
      EXPECT_GT(g, 0.0) << e.name << " (RET " << ret << ")";
    }
  }
}

// Shifting body and garments (and so the root) by a constant leaves the predicted motion
// x̂_{t+1} − x_t unchanged: every input is root-relative (up to the float spacing of world
// positions near 40 units, 3.8e-6: measured difference 5.9e-6).
TEST(ModelInvariance, TranslatingTheSceneKeepsPredictedMotion) {
  const auto c = testing::tiny_config();
  ad::ParamStore<float> ps;
  register_params(ps, c);
  init_params(ps, c, 9);
  const auto stats = dataset::compute_stats(dataset::make_synthetic_sequence(testing::tiny_scene()));
  std::vector<double> motion[2];
  for (int k = 0; k < 2; ++k) {
    auto o = testing::tiny_scene();
    if (k == 1) o.offset = {25.f, -40.f, 7.5f};
    const auto seq = dataset::make_synthetic_sequence(o);
    const auto w = testing::window(seq, stats, c);
    ad::Tape<float> tape;
    ad::NoRecord<float> off(tape);
    const auto x_next = next_positions(forward(tape, ps, c, w.input));
    int64_t v = 0;
    for (int g = 0; g < seq.info.num_garments(); ++g) {
      const auto x_t = seq.garment_at(g, testing::kFrame);
      for (Eigen::Index i = 0; i < x_t.rows(); ++i, ++v)
        for (int j = 0; j < 3; ++j)
          motion[k].push_back(x_next(v, j) + w.sample.root_translation_next[j] - double(x_t(i, j)));
    }
  }
  double max_motion = 0, max_diff = 0;
  for (std::size_t i = 0; i < motion[0].size(); ++i) {
    max_motion = std::max(max_motion, std::abs(motion[0][i]));
    max_diff = std::max(max_diff, std::abs(motion[0][i] - motion[1][i]));
  }
  EXPECT_GT(max_motion, 1e-3);
  std::cout << "max motion " << max_motion << " max diff " << max_diff << "\n";
  EXPECT_LT(max_diff, 1e-5);
}

// A scene without wind runs no wind encoder (2 ops fewer: its fused MLP and 1 row concat),
// the wind parameters get no gradient and cannot influence the output, while the root
// motion (which the official wind token also carries) still reaches the model through the
// gravity token.
TEST(ModelAbsentParts, NoWindSkipsExactlyTheWindToken) {
  const auto c = testing::tiny_config();
  ad::ParamStore<double> ps;
  register_params(ps, c);
  init_params(ps, c, 2);
  const auto stats = dataset::compute_stats(dataset::make_synthetic_sequence(testing::tiny_scene()));
  auto nodes_and_output = [&](const dataset::Sequence& seq, std::vector<double>* out) {
    const auto in = cast_input<double>(testing::window(seq, stats, c).input);
    ad::Tape<double> tape;
    const auto pred = forward(tape, ps, c, in);
    if (out) out->assign(pred.vertex.value, pred.vertex.value + pred.vertex.size());
    ps.zero_grads();
    auto loss = ad::sum_all(tape, pred.vertex);
    tape.backward(loss);
    return static_cast<int64_t>(tape.nodes().size());
  };
  const auto windy = dataset::make_synthetic_sequence(testing::tiny_scene(true));
  const auto calm = dataset::make_synthetic_sequence(testing::tiny_scene(false));
  EXPECT_EQ(nodes_and_output(windy, nullptr) - nodes_and_output(calm, nullptr), 2);
  std::vector<double> base, changed;
  nodes_and_output(calm, &base);
  for (const auto& e : ps.entries())
    if (e.name.rfind("embed.wind.", 0) == 0) {
      for (int64_t k = 0; k < e.size(); ++k) {
        EXPECT_EQ(ps.grads()[e.offset + k], 0.0) << e.name;
        ps.values()[e.offset + k] += 0.5;
      }
    }
  nodes_and_output(calm, &changed);
  EXPECT_EQ(base, changed);  // bit-identical: the wind weights are not used at all
  // Root motion reaches the model: a different root velocity at t+1 (the body moves with the
  // root, so every root-relative position is unchanged) changes the prediction.
  auto moved = calm;
  const int t1 = testing::kFrame + 1;
  moved.info.translation.row(t1).array() += 0.05f;
  for (int b = 0; b < moved.info.num_body_vertices; ++b)
    moved.frames.body.row(static_cast<Eigen::Index>(t1) * moved.info.num_body_vertices + b).array() += 0.05f;
  nodes_and_output(moved, &changed);
  double diff = 0;
  for (std::size_t i = 0; i < base.size(); ++i) diff = std::max(diff, std::abs(base[i] - changed[i]));
  EXPECT_GT(diff, 1e-6);
}

// One garment: no layer-collision term, and its weight then changes nothing (not even the
// tape); with two garments the term is present.
TEST(ModelAbsentParts, OneGarmentHasNoLayerTerm) {
  const auto c = testing::tiny_config();
  ad::ParamStore<double> ps;
  register_params(ps, c);
  init_params(ps, c, 4);
  auto run = [&](int garments, double w_layer, double* total, double* layer) {
    const auto s = make_sample<double>(testing::tiny_scene(true, garments), c);
    LossConfig lc;
    lc.collision_layer = w_layer;
    lc.collision_eps = 0.05;
    ad::Tape<double> tape;
    const auto pred = forward(tape, ps, c, s.input);
    const auto t = losses::compute_losses(tape, ps, c, lc, s.target, pred);
    *total = t.total.scalar();
    *layer = t.collision_layer;
    return static_cast<int64_t>(tape.nodes().size());
  };
  double t0, t1, l0, l1;
  EXPECT_EQ(run(1, 0.1, &t0, &l0), run(1, 0.0, &t1, &l1));
  EXPECT_EQ(t0, t1);
  EXPECT_EQ(l0, 0.0);
  EXPECT_GT(run(2, 0.1, &t0, &l0), run(2, 0.0, &t1, &l1));
  EXPECT_GT(l0, 0.0);
}

// Degenerate scene: the body is far from every garment (no body token at all, U = 0), so
// every patch attends only to patches, wind and gravity, and the decoder uses identity frames.
TEST(ModelAbsentParts, NoBodyNearby) {
  const auto c = testing::tiny_config();
  auto o = testing::tiny_scene();
  const auto stats = dataset::compute_stats(dataset::make_synthetic_sequence(o));
  o.body_offset = {100.f, 0.f, 0.f};
  const auto w = testing::window(dataset::make_synthetic_sequence(o), stats, c);
  const auto in = cast_input<double>(w.input);
  ASSERT_EQ(in.U, 0);
  ad::ParamStore<double> ps;
  register_params(ps, c);
  init_params(ps, c, 8);
  ad::Tape<double> tape;
  const auto pred = forward(tape, ps, c, in);
  const auto target = losses::cast_loss_input<double>(w.target);
  const auto t = losses::compute_losses(tape, ps, c, LossConfig{}, target, pred);
  EXPECT_EQ(t.body_collisions, 0);
  ps.zero_grads();
  tape.backward(t.total);
  for (std::size_t i = 0; i < ps.grads().size(); ++i) ASSERT_TRUE(std::isfinite(ps.grads()[i]));
  for (int64_t i = 0; i < pred.vertex.size(); ++i) ASSERT_TRUE(std::isfinite(pred.vertex.value[i]));
}

}  // namespace
}  // namespace layersnet::model
