// The model predictor with bfloat16 linear products (eval --precision bf16): its name says
// so, and its rollout stays close to the float rollout of the same parameters.
#include "autodiff/bf16_gemm.h"
#include "dataset/synthetic.h"
#include "eval/rollout.h"
#include "model/params_layout.h"
#include "run/config.h"

#include <gtest/gtest.h>

#include <iostream>

namespace layersnet::eval {
namespace {

TEST(RolloutBf16, StaysCloseToTheFloatRollout) {
  dataset::SyntheticOptions o;
  o.garments = 2;
  o.frames = 10;
  o.rings = 4;
  o.segments = 8;
  o.body_rings = 4;
  o.body_segments = 8;
  const dataset::Sequence seq = dataset::make_synthetic_sequence(o);
  const Config c = load_config({std::string(LAYERSNET_SOURCE_DIR) + "/configs/tiny.toml"});
  ad::ParamStore<float> ps;
  model::register_params(ps, c.model);
  model::init_params(ps, c.model, 3);
  ModelPredictor f32("tiny", c, ps, {}), bf16("tiny", c, ps, {});
  bf16.set_matmul_precision(ad::MatmulPrecision::kBFloat16);
  EXPECT_EQ(f32.name(), "tiny");
  EXPECT_EQ(bf16.name(), "[bf16] tiny");
  const Rollout a = rollout(f32, seq, 2, 5), b = rollout(bf16, seq, 2, 5);
  ASSERT_EQ(a.frames.size(), b.frames.size());
  ASSERT_EQ(b.diverged_at, -1);
  // The first step (both start from the ground truth): its difference against the step the
  // model predicts (x_{t+1} − x_t). Later steps of this UNTRAINED model (identity
  // normalisation) move the garment by metres and amplify any difference, so they are only
  // required to stay finite.
  const Points x2 = garments_at(seq, 2);
  const double d0 = (a.frames[0] - b.frames[0]).cwiseAbs().maxCoeff(), step0 = (a.frames[0] - x2).cwiseAbs().maxCoeff();
  std::cout << "first rollout step: max |x_bf16 - x_float| = " << d0 << ", max step " << step0 << " ("
            << ad::bf16_kernel_name() << ")\n";
  EXPECT_GT(d0, 0.0);            // bf16 was used
  EXPECT_LT(d0, 0.01 * step0);   // and changes the step little
  for (const auto& f : b.frames) EXPECT_TRUE(f.allFinite());
}

}  // namespace
}  // namespace layersnet::eval
