// The dataset's training sample drives the model: conversion, forward, losses, backward; the
// model input's neighbour lists and frames against their definitions.
#include "dataset/body_skin.h"
#include "dataset/garments.h"
#include "dataset/sample.h"
#include "dataset/synthetic.h"
#include "dataset/wind.h"
#include "losses/sample_loss_input.h"
#include "model/layersnet.h"
#include "model/params_layout.h"
#include "model/sample_input.h"
#include "model_test_util.h"

#include <gtest/gtest.h>

#include <Eigen/LU>

#include <algorithm>
#include <cmath>
#include <random>

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

// Two garments over ten frames: the scene of the body-base, local-feature and smoothing tests.
dataset::Sequence two_garment_sequence() {
  dataset::SyntheticOptions o;
  o.garments = 2;
  o.frames = 10;
  return dataset::make_synthetic_sequence(o);
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

// velocity_base = "body": the body turned rigidly about the root between t and t+1 carries each
// x_t by that turn, and a freshly initialised network (its output layer starts at zero) predicts
// exactly that step, whatever the velocity statistics.
TEST(SampleInput, BodyVelocityBaseCarriesTheClothWithATurningBody) {
  auto seq = two_garment_sequence();
  const int t = 6;
  const Eigen::Matrix3f R = Eigen::AngleAxisf(0.3f, Eigen::Vector3f(0.2f, 0.1f, 1.f).normalized()).toRotationMatrix();
  const Eigen::Matrix3f R_prev = Eigen::AngleAxisf(-0.2f, Eigen::Vector3f(0.f, 0.3f, 1.f).normalized()).toRotationMatrix();
  // Frame f + 1's body: frame f's turned by `turn` about the root.
  auto turn_next = [&](int f, const Eigen::Matrix3f& turn) {
    dataset::Points body = seq.body_at(f);
    body.rowwise() -= seq.info.translation.row(f);
    dataset::Points turned = body * turn.transpose();
    turned.rowwise() += seq.info.translation.row(f + 1);
    seq.frames.body.middleRows(static_cast<Eigen::Index>(f + 1) * seq.info.num_body_vertices,
                               seq.info.num_body_vertices) = turned;
  };
  turn_next(t - 1, R_prev);
  turn_next(t, R);
  const auto st = stats();
  ModelConfig c = testing::tiny_config();
  c.velocity_base = "body";
  const auto sample = dataset::build_sample(seq.info, seq.frames, t, st, nullptr, sample_options_for(c));
  const int N = sample.num_vertices();
  ASSERT_EQ(sample.body_carry.rows(), N);
  const dataset::Points x_t = sample.state.leftCols<3>();
  const dataset::Points expected = x_t * R.transpose() - x_t;
  EXPECT_LT((sample.body_carry - expected).cwiseAbs().maxCoeff(), 1e-4f);
  EXPECT_GT(expected.cwiseAbs().maxCoeff(), 0.1f);  // the turn moves the cloth by more than the tolerance

  const auto in = model_input_from_sample(sample, st, c);
  ad::ParamStore<float> ps;
  register_params(ps, c);
  init_params(ps, c, 1);
  ad::Tape<float> tape;
  const auto pred = forward(tape, ps, c, in);
  for (int v = 0; v < N; ++v)
    for (int k = 0; k < 3; ++k)
      EXPECT_NEAR(pred.vertex.value[3 * 3 * v + k], x_t(v, k) + expected(v, k), 1e-4f) << v;
  // The official base keeps the cloth's velocity instead, and adds the mean velocity twice (patch
  // and vertex).
  c.velocity_base = "inertia";
  const auto inertial = forward(tape, ps, c, model_input_from_sample(sample, st, c));
  for (int k = 0; k < 3; ++k)
    EXPECT_NEAR(inertial.vertex.value[k], x_t(0, k) + sample.state(0, 3 + k) + 2 * st.velocity.mean[k], 1e-4f);
  // "body_inertia" adds the velocity relative to the body at t: v_t − c_t, c_t = R_prev x_{t-1} − x_{t-1}.
  c.velocity_base = "body_inertia";
  const auto relative_sample = dataset::build_sample(seq.info, seq.frames, t, st, nullptr, sample_options_for(c));
  const dataset::Points x_prev = relative_sample.state.middleCols<3>(6);
  const dataset::Points carry_prev = x_prev * R_prev.transpose() - x_prev;
  EXPECT_LT((relative_sample.body_carry_prev - carry_prev).cwiseAbs().maxCoeff(), 1e-4f);
  EXPECT_GT(carry_prev.cwiseAbs().maxCoeff(), 0.1f);
  const auto relative = forward(tape, ps, c, model_input_from_sample(relative_sample, st, c));
  for (int v = 0; v < N; ++v)
    for (int k = 0; k < 3; ++k)
      EXPECT_NEAR(relative.vertex.value[9 * v + k],
                  x_t(v, k) + expected(v, k) + relative_sample.state(v, 3 + k) - carry_prev(v, k), 1e-4f) << v;
  // model.swing_kept keeps that share of the relative velocity.
  c.swing_kept = 0.25;
  const auto damped = forward(tape, ps, c, model_input_from_sample(relative_sample, st, c));
  for (int v = 0; v < N; ++v)
    for (int k = 0; k < 3; ++k)
      EXPECT_NEAR(damped.vertex.value[9 * v + k],
                  x_t(v, k) + expected(v, k) + 0.25f * (relative_sample.state(v, 3 + k) - carry_prev(v, k)), 1e-4f) << v;
  c.swing_kept = 1.0;
  // A body-based model refuses a sample built without the carry.
  c.velocity_base = "body";
  const auto bare = dataset::build_sample(seq.info, seq.frames, t, st, nullptr);
  EXPECT_THROW(model_input_from_sample(bare, st, c), std::exception);
}

// Each block of ModelInput::vertex_local recomputed here from the sequence itself.
TEST(SampleInput, VertexLocalFeaturesAreWhatTheirNamesSay) {
  const auto seq = two_garment_sequence();
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


// ModelInput::wind_force recomputed from the sequence's faces at x_t: the face wind of the wind at
// t+1 divided by the garment's mean vertex area share; its patch means; empty without wind or
// with the switch off; linear in the strength.
TEST(SampleInput, WindForceIsTheFaceWindPerMeanVertexArea) {
  dataset::SyntheticOptions o;
  o.garments = 2;
  o.frames = 10;
  o.wind = true;
  const auto seq = dataset::make_synthetic_sequence(o);
  const auto st = stats();
  const int t = 6;
  ASSERT_TRUE(seq.info.has_wind);
  ASSERT_GT(seq.info.wind_strength[t + 1], 0.f);
  const auto sample = dataset::build_sample(seq.info, seq.frames, t, st, nullptr);
  ModelConfig c = testing::tiny_config();
  EXPECT_TRUE(model_input_from_sample(sample, st, c).wind_force.empty());
  c.wind_force_input = true;
  const auto in = model_input_from_sample(sample, st, c);
  ASSERT_EQ(in.wind_force.size(), static_cast<std::size_t>(3 * in.N));
  const auto x = dataset::garments_at(seq.info, seq.frames, t);
  const Eigen::Vector3d w = seq.info.wind_strength[t + 1] / 400.0 *
                            dataset::wind_direction(seq.info.wind_rotation.row(t + 1).transpose()).cast<double>();
  std::vector<Eigen::Vector3d> force(in.N, Eigen::Vector3d::Zero());
  std::vector<double> area(in.N, 0.0);
  int offset = 0, facing = 0;
  for (const auto& g : seq.info.garments) {
    for (Eigen::Index f = 0; f < g.faces.rows(); ++f) {
      const Eigen::Vector3d a = x.row(offset + g.faces(f, 0)).transpose().cast<double>();
      const Eigen::Vector3d b = x.row(offset + g.faces(f, 1)).transpose().cast<double>();
      const Eigen::Vector3d d = x.row(offset + g.faces(f, 2)).transpose().cast<double>();
      const Eigen::Vector3d n = (b - a).cross(d - a);
      const double A = n.norm() / 2;
      for (int k = 0; k < 3; ++k) {
        force[offset + g.faces(f, k)] += A / 3 * w.dot(n.normalized()) * n.normalized();
        area[offset + g.faces(f, k)] += A / 3;
      }
    }
    double mean = 0;
    for (int v = offset; v < offset + g.num_vertices; ++v) mean += area[v] / g.num_vertices;
    for (int v = offset; v < offset + g.num_vertices; ++v) {
      const Eigen::Vector3f got(in.wind_force[3 * v], in.wind_force[3 * v + 1], in.wind_force[3 * v + 2]);
      EXPECT_LT((got.cast<double>() - force[v] / mean).norm(), 1e-5 * (1 + force[v].norm() / mean)) << v;
      facing += got.norm() > 1e-3f;
    }
    offset += g.num_vertices;
  }
  EXPECT_GT(facing, in.N / 4);  // the feature is not all zeros
  const auto& all = sample.structure->all;
  for (int p = 0; p < in.P; ++p) {
    Eigen::Vector3f mean = Eigen::Vector3f::Zero();
    for (const int32_t* v = all.patch_vertices.begin(p); v != all.patch_vertices.end(p); ++v)
      mean += Eigen::Vector3f(in.wind_force[3 * *v], in.wind_force[3 * *v + 1], in.wind_force[3 * *v + 2]);
    mean /= static_cast<float>(all.patch_vertices.size(p));
    for (int k = 0; k < 3; ++k) EXPECT_NEAR(in.wind_force_patch[3 * p + k], mean[k], 1e-5f) << p;
  }
  // Half the strength, half the feature (eval --wind-scale scales the strength).
  auto halved = seq;
  halved.info.wind_strength *= 0.5f;
  const auto in_half = model_input_from_sample(dataset::build_sample(halved.info, halved.frames, t, st, nullptr), st, c);
  for (std::size_t i = 0; i < in.wind_force.size(); ++i)
    EXPECT_NEAR(in_half.wind_force[i], 0.5f * in.wind_force[i], 1e-6f * (1 + std::abs(in.wind_force[i])));
  // No wind, no feature.
  o.wind = false;
  const auto calm = dataset::make_synthetic_sequence(o);
  EXPECT_TRUE(model_input_from_sample(dataset::build_sample(calm.info, calm.frames, t, st, nullptr), st, c).wind_force.empty());
}

using Mat3 = Eigen::Matrix<double, 3, 3, Eigen::RowMajor>;

// normal_frame(n) is a rotation R (orthonormal, det 1) with R n = e_z, each within `tol`.
void expect_rotation_to_z(const Eigen::Vector3d& n, double tol) {
  double R[9];
  normal_frame(n.data(), R);
  const Eigen::Map<const Mat3> M(R);
  EXPECT_LT((M * M.transpose() - Mat3::Identity()).norm(), tol) << n.transpose();
  EXPECT_NEAR(M.determinant(), 1.0, tol) << n.transpose();
  EXPECT_LT((M * n - Eigen::Vector3d::UnitZ()).norm(), tol) << n.transpose();
}

TEST(NormalFrame, RotationsWithTheNormalLast) {
  std::vector<Eigen::Vector3d> normals = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}, {-1, 0, 0}, {0, 0, -1},
                                          {1, 1e-8, 0}, {1e-9, -1e-9, 1}, {1, 1, 1}, {0, 1, 1e-6}};
  std::mt19937_64 rng(1);
  std::normal_distribution<double> g(0, 1);
  for (int k = 0; k < 200; ++k) normals.push_back({g(rng), g(rng), g(rng)});
  for (const auto& n : normals) expect_rotation_to_z(n.normalized(), 1e-12);
  const double zero[3] = {0, 0, 0};
  double R[9];
  normal_frame(zero, R);
  EXPECT_EQ(Eigen::Map<const Mat3>(R), Mat3::Identity());
}

// Components just above the official 1e-7 rule leave x0 = (1, 0, 0) nearly parallel to n: one
// Gram-Schmidt pass then cancels (measured: R n off e_z by 2.3e-10 for 2e-7 components), still far
// below the float precision of ModelInput::body_rot and gravity_rot.
TEST(NormalFrame, NearAxisNormalsWithinFloatPrecision) {
  const std::vector<Eigen::Vector3d> normals = {{1, 2e-7, -2e-7}, {3e-7, 1, 0}, {-2e-7, 0, -1}, {1, 1e-4, 0}};
  for (const auto& n : normals) expect_rotation_to_z(n.normalized(), 1e-6);
}

// model.output_smoothing averages the network's per-vertex correction over the garment mesh with
// the carry's operator (dataset::smooth_over_mesh), and moves x and v by the same change.
TEST(SampleInput, OutputSmoothingAveragesTheCorrectionOverTheMesh) {
  const auto seq = two_garment_sequence();
  const auto st = stats();
  ModelConfig c = testing::tiny_config();
  c.velocity_base = "body";
  const auto sample = dataset::build_sample(seq.info, seq.frames, 6, st, nullptr, sample_options_for(c));
  const int N = sample.num_vertices();
  ad::ParamStore<float> ps;
  register_params(ps, c);
  init_params(ps, c, 1);
  std::mt19937 rng(5);  // a nonzero output layer: the zero one predicts no correction to smooth
  std::normal_distribution<float> normal(0.f, 0.3f);
  for (float& w : ps.value(ps.index_of("decoder.proj.2.weight"))) w = normal(rng);
  ad::Tape<float> tape;
  const auto raw = forward(tape, ps, c, model_input_from_sample(sample, st, c));
  c.output_smoothing = 3;
  const auto in = model_input_from_sample(sample, st, c);
  const auto smooth = forward(tape, ps, c, in);
  dataset::Points correction(N, 3), expected;
  for (int v = 0; v < N; ++v)
    for (int k = 0; k < 3; ++k) correction(v, k) = raw.vertex.value[9 * v + 6 + k];
  expected = correction;
  dataset::smooth_over_mesh(expected, sample.structure->vertex_neighbours, 3);
  float moved = 0;
  for (int v = 0; v < N; ++v)
    for (int k = 0; k < 3; ++k) {
      const float change = expected(v, k) - correction(v, k);
      moved = std::max(moved, std::abs(change));
      EXPECT_NEAR(smooth.vertex.value[9 * v + 6 + k], expected(v, k), 1e-5f) << v;
      EXPECT_NEAR(smooth.vertex.value[9 * v + k], raw.vertex.value[9 * v + k] + change, 1e-5f) << v;
      EXPECT_NEAR(smooth.vertex.value[9 * v + 3 + k], raw.vertex.value[9 * v + 3 + k] + change, 1e-5f) << v;
    }
  EXPECT_GT(moved, 1e-3f);  // the raw correction differs between neighbours
  // A model that smooths refuses an input built without the neighbours.
  c.output_smoothing = 0;
  const auto bare = model_input_from_sample(sample, st, c);
  c.output_smoothing = 3;
  EXPECT_THROW(forward(tape, ps, c, bare), std::exception);
}

TEST(NormalFrame, OfficialFirstAxisRuleAndNonUnitInput) {
  // n = e_z: x0 = (1, 0, 0) plus ones where |n_c| < 1e-7 -> (1, 1, 0); x = (1, 1, 0)/sqrt(2).
  // n = e_x: x0 = (1, 1, 1) -> x = (0, 1, 1)/sqrt(2). n = (0.6, 0.8, 0): x0 = (1, 0, 1).
  const double s = std::sqrt(0.5);
  double R[9];
  const double ez[3] = {0, 0, 1}, ex[3] = {1, 0, 0}, n3[3] = {0.6, 0.8, 0};
  normal_frame(ez, R);
  EXPECT_TRUE(Eigen::Vector3d(R[0], R[1], R[2]).isApprox(Eigen::Vector3d(s, s, 0)));
  normal_frame(ex, R);
  EXPECT_TRUE(Eigen::Vector3d(R[0], R[1], R[2]).isApprox(Eigen::Vector3d(0, s, s)));
  normal_frame(n3, R);
  const Eigen::Vector3d x = (Eigen::Vector3d(1, 0, 1) - 0.6 * Eigen::Vector3d(0.6, 0.8, 0)).normalized();
  EXPECT_TRUE(Eigen::Vector3d(R[0], R[1], R[2]).isApprox(x));
  EXPECT_TRUE(Eigen::Vector3d(R[3], R[4], R[5]).isApprox(Eigen::Vector3d(0.6, 0.8, 0).cross(x)));
  // A non-unit vector (the gravity direction g/fps - a_root) gives the frame of its direction.
  const double n2[3] = {1.2, 1.6, 0};
  double R2[9];
  normal_frame(n2, R2);
  for (int k = 0; k < 9; ++k) EXPECT_NEAR(R2[k], R[k], 1e-15) << k;
}

TEST(SampleInput, NeighbourListsFollowTheirDefinitions) {
  const auto c = testing::tiny_config();
  const auto in = testing::window(dataset::make_synthetic_sequence(testing::tiny_scene()), c).input;
  auto centre = [&](int p) { return Eigen::Vector3f(&in.patch_state[12 * p]); };
  const float r = static_cast<float>(c.world_radius);
  for (int i = 0; i < in.P; ++i) {
    const auto mb = in.mesh_senders.begin() + in.mesh_offsets[i], me = in.mesh_senders.begin() + in.mesh_offsets[i + 1];
    EXPECT_NE(std::find(mb, me, i), me) << "a patch is mesh-adjacent to itself";
    for (int j = 0; j < in.P; ++j) {  // squared distances in float, as the grid compares them
      const bool near = j != i && (centre(i) - centre(j)).squaredNorm() < r * r && std::find(mb, me, j) == me;
      const auto wb = in.world_senders.begin() + in.world_offsets[i], we = in.world_senders.begin() + in.world_offsets[i + 1];
      EXPECT_EQ(near, std::find(wb, we, j) != we) << i << " -> " << j;
    }
    EXPECT_LE(in.body_offsets[i + 1] - in.body_offsets[i], c.body_neighbors);
  }
  EXPECT_GT(in.world_senders.size(), 0u);
  EXPECT_GT(in.body_tokens.size(), 0u);
  // Decoder candidates: at most 4, all mesh-adjacent to the vertex's own patch.
  for (int v = 0; v < in.N; ++v) {
    const int own = in.own_patch[v];
    EXPECT_LE(in.cand_offsets[v + 1] - in.cand_offsets[v], c.decoder_patch_candidates);
    for (int k = in.cand_offsets[v]; k < in.cand_offsets[v + 1]; ++k) {
      const auto mb = in.mesh_senders.begin() + in.mesh_offsets[own], me = in.mesh_senders.begin() + in.mesh_offsets[own + 1];
      EXPECT_NE(std::find(mb, me, in.cand_patches[k]), me);
    }
  }
  // Patch states are the means of their members' states (float sums, as the data layer's).
  for (int p = 0; p < in.P; ++p) {
    float sum = 0;
    for (int k = in.p2v_offsets[p]; k < in.p2v_offsets[p + 1]; ++k) sum += in.state[12 * in.p2v_vertices[k] + 4];
    EXPECT_FLOAT_EQ(in.patch_state[12 * p + 4], sum / static_cast<float>(in.p2v_offsets[p + 1] - in.p2v_offsets[p]));
  }
}

// The searches use the data layer's grid / k-d tree; here the brute-force definitions:
// body lists = the K nearest body vertices (t+1) within R_b of each patch centre, and
// patch_body / vertex_body = the nearest body vertex if within R_b.
TEST(SampleInput, BodyListsAndNearestFollowTheirDefinitions) {
  const auto c = testing::tiny_config();
  const auto seq = dataset::make_synthetic_sequence(testing::tiny_scene());
  const auto w = testing::window(seq, c);
  const auto& in = w.input;
  const int64_t B = seq.info.num_body_vertices;
  const Eigen::Vector3d root = seq.info.translation.row(testing::kFrame + 1).transpose().cast<double>();
  auto body = [&](int64_t b) {
    return Eigen::Vector3d(seq.body_at(testing::kFrame + 1).row(b).transpose().cast<double>() - root);
  };
  // Token -> body vertex: the vertex whose normalised state the token carries.
  std::vector<int64_t> vertex_of(in.U, -1);
  for (int64_t u = 0; u < in.U; ++u) {
    for (int64_t b = 0; b < B; ++b)
      if (std::equal(&in.body_norm[12 * u], &in.body_norm[12 * u] + 12, w.sample.body_state_norm.row(b).data()))
        vertex_of[u] = b;
    ASSERT_GE(vertex_of[u], 0) << "token " << u;
  }
  auto nearest = [&](const Eigen::Vector3d& q) {
    int64_t best = 0;
    for (int64_t b = 1; b < B; ++b)
      if ((body(b) - q).norm() < (body(best) - q).norm()) best = b;
    return best;
  };
  for (int64_t p = 0; p < in.P; ++p) {
    const Eigen::Vector3d cp = Eigen::Vector3f(&in.patch_state[12 * p]).cast<double>();
    std::vector<std::pair<double, int64_t>> hits;
    for (int64_t b = 0; b < B; ++b)
      if ((body(b) - cp).norm() < c.body_radius) hits.emplace_back((body(b) - cp).norm(), b);
    std::sort(hits.begin(), hits.end());
    hits.resize(std::min<std::size_t>(hits.size(), static_cast<std::size_t>(c.body_neighbors)));
    std::vector<int64_t> want, got;
    for (const auto& h : hits) want.push_back(h.second);
    for (int k = in.body_offsets[p]; k < in.body_offsets[p + 1]; ++k) got.push_back(vertex_of[in.body_tokens[k]]);
    EXPECT_EQ(got, want) << "patch " << p;
    const int64_t nb = nearest(cp);
    EXPECT_EQ(in.patch_body[p] >= 0, (body(nb) - cp).norm() < c.body_radius) << "patch " << p;
    if (in.patch_body[p] >= 0) {
      EXPECT_EQ(vertex_of[in.patch_body[p]], nb) << "patch " << p;
    }
  }
  int near_vertices = 0;
  for (int64_t v = 0; v < in.N; ++v) {
    const Eigen::Vector3d x(in.state[12 * v], in.state[12 * v + 1], in.state[12 * v + 2]);
    const int64_t nb = nearest(x);
    const bool within = (body(nb) - x).norm() < c.body_radius;
    EXPECT_EQ(in.vertex_body[v] >= 0, within) << "vertex " << v;
    if (within) {
      EXPECT_EQ(vertex_of[in.vertex_body[v]], nb) << "vertex " << v;
      ++near_vertices;
    }
  }
  EXPECT_GT(near_vertices, 0);
}

}  // namespace
}  // namespace layersnet::model
