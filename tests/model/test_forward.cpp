// Forward pass: shapes, finiteness, parameter layout and counts.
#include "autodiff/ops_dense.h"
#include "autodiff/ops_graph.h"
#include "model/layersnet.h"
#include "model/params_layout.h"
#include "model_test_util.h"

#include <gtest/gtest.h>

#include <cmath>
#include <iostream>

namespace layersnet::model {
namespace {

// One forward: `out` gets the vertex predictions (then the patch ones when `with_patch`), `grad`
// the parameter gradient of their sum.
void run_forward(ad::ParamStore<double>& ps, const ModelConfig& c, const ModelInput<double>& in, const ForwardOptions& opt,
                 bool with_patch, std::vector<double>& out, std::vector<double>& grad) {
  ad::Tape<double> tape;
  const auto pred = forward(tape, ps, c, in, opt);
  out.assign(pred.vertex.value, pred.vertex.value + pred.vertex.size());
  if (with_patch) out.insert(out.end(), pred.patch.value, pred.patch.value + pred.patch.size());
  ps.zero_grads();
  tape.backward(ad::sum_all(tape, with_patch ? ad::concat_rows(tape, pred.vertex, pred.patch) : pred.vertex));
  grad.assign(ps.grads().begin(), ps.grads().end());
}

TEST(ModelParams, OfficialSizesMatchTheReferenceCount) {
  ModelConfig c;  // official sizes
  ad::ParamStore<float> ps;
  register_params(ps, c);
  int64_t total = 0;
  for (const auto& e : ps.entries()) total += e.size();
  std::cout << "official-size parameters: registered " << total << ", official layout "
            << official_parameter_count(c) << "\n";
  EXPECT_EQ(official_parameter_count(c), 1018719);  // counted from the official code's shapes: 873,728 + 144,991
  // Our decoder RET map has k channels (d, 3k) where the official one is (d, 3).
  // We do not register the last layer's dead r_proj, s_proj and res_norms.
  EXPECT_EQ(total, 1018719 - 2 * (128 * 128 + 128) - 4 * 128 + 128 * 3 * (c.decoder_ret_channels - 1));
  EXPECT_EQ(ps.index_of("encoder.layers.0.attn.q_proj.weight") >= 0, true);
  EXPECT_THROW(ps.index_of("encoder.layers.3.attn.r_proj.weight"), std::exception);
}

TEST(ModelParams, RotationMapsStartOrthonormal) {
  ModelConfig c;
  ad::ParamStore<double> ps;
  register_params(ps, c);
  init_params(ps, c, 7);
  for (const auto& name : rotation_map_names(c)) {
    auto v = ps.var(name);
    Eigen::MatrixXd WtW = v.val().transpose() * v.val();
    EXPECT_LT((WtW - Eigen::MatrixXd::Identity(WtW.rows(), WtW.cols())).norm(), 1e-12) << name;
  }
}

TEST(ModelForward, ShapesAndFiniteOutputs) {
  const ModelConfig c = testing::tiny_config();
  const auto in = testing::window(dataset::make_synthetic_sequence(testing::tiny_scene()), c).input;
  ad::ParamStore<float> ps;
  register_params(ps, c);
  init_params(ps, c, 1);
  ad::Tape<float> tape;
  const auto pred = forward(tape, ps, c, in);
  ASSERT_EQ(pred.vertex.rows, in.N);
  ASSERT_EQ(pred.vertex.cols, 9);
  ASSERT_EQ(pred.patch.rows, in.P);
  for (int64_t i = 0; i < pred.vertex.size(); ++i) ASSERT_TRUE(std::isfinite(pred.vertex.value[i]));
}

// The rank-3 factored decoder is the same function as the explicit φ(R) one, with the same
// gradients; also with the extra first-layer columns (local features, the wind force) drawn.
TEST(ModelForward, FactoredDecoderEqualsExplicit) {
  for (const bool extras : {false, true}) {
    ModelConfig c = testing::tiny_config();
    c.vertex_local_features = c.wind_force_input = extras;
    const auto in = cast_input<double>(testing::window(dataset::make_synthetic_sequence(testing::tiny_scene()), c).input);
    ASSERT_EQ(in.wind_force.empty(), !extras);
    ad::ParamStore<double> ps;
    register_params(ps, c);
    init_params(ps, c, 4);
    if (extras) {
      testing::draw_normal(ps, "decoder.wind.weight", 9);
      testing::draw_normal(ps, "embed.wind_force.weight", 10);
    }
    std::vector<double> out[2], grad[2];
    for (int k = 0; k < 2; ++k) {
      ForwardOptions opt;
      opt.factor_decoder = k == 0;
      run_forward(ps, c, in, opt, true, out[k], grad[k]);
    }
    ASSERT_EQ(out[0].size(), out[1].size());
    for (std::size_t i = 0; i < out[0].size(); ++i) ASSERT_NEAR(out[0][i], out[1][i], 1e-12) << i << " extras " << extras;
    double gmax = 0, dmax = 0;
    for (std::size_t i = 0; i < grad[0].size(); ++i)
      gmax = std::max(gmax, std::abs(grad[1][i])), dmax = std::max(dmax, std::abs(grad[0][i] - grad[1][i]));
    EXPECT_GT(gmax, 0.0);
    EXPECT_LT(dmax, 1e-10 * gmax) << "extras " << extras;
  }
}

// The fused RIA op and the gather/segment composite give the same model (up to how eps
// enters the distance) and the same gradients.
TEST(ModelForward, FusedAttentionEqualsComposite) {
  const ModelConfig c = testing::tiny_config();
  const auto in = cast_input<double>(testing::window(dataset::make_synthetic_sequence(testing::tiny_scene()), c).input);
  ad::ParamStore<double> ps;
  register_params(ps, c);
  init_params(ps, c, 6);
  std::vector<double> out[2], grad[2];
  for (int k = 0; k < 2; ++k) {
    ForwardOptions opt;
    opt.fused_attention = k == 0;
    run_forward(ps, c, in, opt, false, out[k], grad[k]);
  }
  double omax = 0, odiff = 0, gmax = 0, gdiff = 0;
  for (std::size_t i = 0; i < out[0].size(); ++i)
    omax = std::max(omax, std::abs(out[1][i])), odiff = std::max(odiff, std::abs(out[0][i] - out[1][i]));
  for (std::size_t i = 0; i < grad[0].size(); ++i)
    gmax = std::max(gmax, std::abs(grad[1][i])), gdiff = std::max(gdiff, std::abs(grad[0][i] - grad[1][i]));
  EXPECT_LT(odiff, 1e-6 * omax);
  EXPECT_LT(gdiff, 1e-5 * gmax);
}

}  // namespace
}  // namespace layersnet::model
