// The dataset's training sample drives the model: conversion, forward, losses, backward.
#include "dataset/sample.h"
#include "dataset/synthetic.h"
#include "losses/sample_loss_input.h"
#include "model/layersnet.h"
#include "model/params_layout.h"
#include "model/sample_input.h"
#include "model_test_util.h"

#include <gtest/gtest.h>

#include <cmath>

namespace layersnet::model {
namespace {

dataset::NormalisationStats stats() {
  dataset::NormalisationStats s;
  s.position = {Eigen::Vector3d(0.1, 0.2, 1.0), Eigen::Vector3d(2, 2, 4), 1};
  s.velocity = {Eigen::Vector3d(0.0, 0.01, 0.0), Eigen::Vector3d(0.5, 0.5, 0.25), 1};
  s.acceleration = {Eigen::Vector3d(0, 0, -0.1), Eigen::Vector3d(0.1, 0.1, 0.2), 1};
  s.root_velocity = {Eigen::Vector3d(0, 0, 0), Eigen::Vector3d(0.1, 0.1, 1), 1};
  s.root_acceleration = {Eigen::Vector3d(0, 0, 0), Eigen::Vector3d(0.01, 0.01, 1), 1};
  return s;
}

TEST(SampleInput, DatasetSampleTrainsTheModel) {
  for (const bool wind : {false, true}) {
    dataset::SyntheticOptions o;
    o.garments = 2;
    o.wind = wind;
    o.frames = 10;
    const auto seq = dataset::make_synthetic_sequence(o);
    const auto st = stats();
    const int t = 7;  // wind (if any) blows from frame 3 on
    const auto sample = dataset::build_sample(seq.info, seq.frames, t, st, nullptr);
    const ModelConfig c = testing::tiny_config();
    const auto in = model_input_from_sample(sample, st, c);
    EXPECT_EQ(in.has_wind, sample.has_wind);
    EXPECT_EQ(in.N, sample.num_vertices());
    EXPECT_GT(in.U, 0);
    EXPECT_GT(in.body_tokens.size(), 0u);
    // The gravity frame is a rotation whose third row is the unit direction of g/fps - a_root.
    Eigen::Map<const Eigen::Matrix<float, 3, 3, Eigen::RowMajor>> Rg(in.gravity_rot.data());
    EXPECT_LT((Rg * Rg.transpose() - Eigen::Matrix3f::Identity()).norm(), 1e-5);
    EXPECT_LT(Rg(2, 2), -0.9f);  // gravity points down (-z) and the root barely accelerates
    const auto target = losses::loss_input_from_sample(sample, seq.info);
    ad::ParamStore<float> ps;
    register_params(ps, c);
    init_params(ps, c, 1);
    ad::Tape<float> tape;
    const auto pred = forward(tape, ps, c, in);
    const auto terms = losses::compute_losses(tape, ps, c, LossConfig{}, target, pred);
    ASSERT_TRUE(std::isfinite(terms.total.scalar()));
    ps.zero_grads();
    tape.backward(terms.total);
    for (const auto& e : ps.entries()) {
      double g = 0;
      for (int64_t k = 0; k < e.size(); ++k) g += std::abs(ps.grads()[e.offset + k]);
      if (!wind && e.name.rfind("embed.wind.", 0) == 0) {
        EXPECT_EQ(g, 0.0) << e.name;
      } else {
        EXPECT_GT(g, 0.0) << e.name << " (wind " << wind << ")";
      }
    }
    EXPECT_GT(terms.vertex, 0.0);
  }
}

}  // namespace
}  // namespace layersnet::model
