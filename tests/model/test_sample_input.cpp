// The dataset's training sample drives the model: conversion, forward, losses, backward.
#include "dataset/garments.h"
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
  for (const bool local : {false, true})
  for (const bool wind : {false, true}) {
    dataset::SyntheticOptions o;
    o.garments = 2;
    o.wind = wind;
    o.frames = 10;
    const auto seq = dataset::make_synthetic_sequence(o);
    const auto st = stats();
    const int t = 7;  // wind (if any) blows from frame 3 on
    const auto sample = dataset::build_sample(seq.info, seq.frames, t, st, nullptr);
    ModelConfig c = testing::tiny_config();
    c.vertex_local_features = local;
    const auto in = model_input_from_sample(sample, st, c);
    EXPECT_EQ(in.vertex_local.size(), local ? static_cast<std::size_t>(in.N * kVertexLocalDim) : 0u);
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
        EXPECT_GT(g, 0.0) << e.name << " (wind " << wind << ", local features " << local << ")";
      }
    }
    EXPECT_GT(terms.vertex, 0.0);
  }
}

// Each block of ModelInput::vertex_local recomputed here from the sequence itself.
TEST(SampleInput, VertexLocalFeaturesAreWhatTheirNamesSay) {
  dataset::SyntheticOptions o;
  o.garments = 2;
  o.frames = 10;
  const auto seq = dataset::make_synthetic_sequence(o);
  const auto st = stats();
  const int t = 6;
  const auto sample = dataset::build_sample(seq.info, seq.frames, t, st, nullptr);
  ModelConfig c = testing::tiny_config();
  c.vertex_local_features = true;
  const auto in = model_input_from_sample(sample, st, c);
  const float rb = static_cast<float>(c.body_radius), sigma_v = (0.5f + 0.5f + 0.25f) / 3.f;
  const auto x = dataset::garments_at(seq.info, seq.frames, t), x_prev = dataset::garments_at(seq.info, seq.frames, t - 1);
  const auto x_prev2 = dataset::garments_at(seq.info, seq.frames, t - 2);
  int near_body = 0;
  for (int64_t v = 0; v < in.N; ++v) {
    const float* f = &in.vertex_local[kVertexLocalDim * v];
    auto block = [&](int b) { return Eigen::Vector3f(f[3 * b], f[3 * b + 1], f[3 * b + 2]); };
    // Last acceleration: translation-free, so the absolute frames give it too.
    const Eigen::Vector3f acc = (x.row(v) - 2 * x_prev.row(v) + x_prev2.row(v)).transpose();
    const Eigen::Vector3f root_acc = (seq.info.translation.row(t) - 2 * seq.info.translation.row(t - 1) +
                                      seq.info.translation.row(t - 2)).transpose();
    EXPECT_LT((block(6) - (acc - root_acc) / sigma_v).norm(), 1e-4f) << "vertex " << v;
    // Laplacian over the mesh neighbours, from the faces.
    const auto& nb = sample.structure->vertex_neighbours;
    ASSERT_GT(nb.size(static_cast<int>(v)), 0);
    Eigen::Vector3f lap = Eigen::Vector3f::Zero();
    for (const int32_t* j = nb.begin(static_cast<int>(v)); j != nb.end(static_cast<int>(v)); ++j)
      lap += (x.row(*j) - x.row(v)).transpose();
    lap /= static_cast<float>(nb.size(static_cast<int>(v)));
    EXPECT_LT((block(4) - lap / rb).norm(), 1e-4f) << "vertex " << v;
    // Body blocks exist only within R_b of a body vertex.
    const bool near = sample.vertex_nearest_body.distance[v] < rb;
    near_body += near;
    if (!near) EXPECT_EQ(block(0).norm() + block(1).norm() + block(2).norm(), 0.f) << "vertex " << v;
    else EXPECT_NEAR(block(0).norm() * rb, (sample.state.row(v).segment<3>(0) - sample.body_state.row(sample.vertex_nearest_body.index[v]).segment<3>(6)).norm(), 1e-4f);
  }
  EXPECT_GT(near_body, 0);
  EXPECT_LT(near_body, in.N);  // the outer layer lies beyond R_b in parts: both branches are tested
}

}  // namespace
}  // namespace layersnet::model
