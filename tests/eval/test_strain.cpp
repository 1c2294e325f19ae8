// Edge strain of rollouts (hand-computed cases, scaled garments, diverged rollouts) and where
// `evaluate` starts a rollout (after the generator's ramp, or a fixed input frame).
#include "dataset/h5.h"
#include "dataset/synthetic.h"
#include "eval/evaluate.h"
#include "eval/rollout.h"
#include "eval/stress.h"
#include "test_predictors.h"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <limits>
#include <unistd.h>

namespace layersnet::eval {
namespace {

namespace fs = std::filesystem;

using testing::sequence;

TEST(Strain, QuantileInterpolatesLinearly) {
  EXPECT_DOUBLE_EQ(quantile({4, 1, 3, 2}, 0.5), 2.5);
  EXPECT_DOUBLE_EQ(quantile({4, 1, 3, 2}, 1.0), 4.0);
  EXPECT_DOUBLE_EQ(quantile({7}, 0.99), 7.0);
  EXPECT_EQ(quantile({}, 0.99), 0.0);
}

TEST(Strain, GroundTruthStrainEqualsAHandComputation) {
  // One garment, one triangle: rest (0,0,0), (1,0,0), (0,1,0) -> edges 01, 12, 20 of rest
  // length 1, sqrt 2, 1. Frame t stretches x by sx[t] (and moves it), so the strains are
  // |sx - 1|, |sqrt(sx^2 + 1) / sqrt 2 - 1| and 0.
  const float sx[] = {1.f, 1.f, 1.f, 1.2f, 0.9f};
  dataset::Sequence seq = sequence(1, 5);
  dataset::GarmentMesh& g = seq.info.garments[0];
  g.num_vertices = 3;
  g.faces.resize(1, 3);
  g.faces << 0, 1, 2;
  g.uv = dataset::Uvs::Zero(3, 2);
  g.panel = {0};
  g.rest.resize(3, 3);
  g.rest << 0, 0, 0, 1, 0, 0, 0, 1, 0;
  seq.frames.garments[0].resize(5 * 3, 3);
  for (int t = 0; t < 5; ++t) {
    auto x = seq.frames.garments[0].middleRows(3 * t, 3);
    x = g.rest;
    x.col(0) *= sx[t];
    x.rowwise() += Eigen::RowVector3f(0.5f, 0.25f, 1.f + 0.1f * t);
  }
  GroundTruth gt;
  const SequenceResult s = score_rollout(seq, rollout(gt, seq, 2, 2), {});  // frames 3 and 4
  const double a3 = 0.2, b3 = std::sqrt(1.22) - 1;  // frame 3: sx = 1.2
  const double a4 = 0.1, b4 = 1 - std::sqrt(0.905);  // frame 4: sx = 0.9
  EXPECT_NEAR(s.strain_mean, (a3 + b3 + 0 + a4 + b4 + 0) / 6, 1e-6);
  // 99th percentile of the 6 values 0, 0, b4, a4, b3, a3: rank 0.99 * 5 = 4.95.
  EXPECT_NEAR(s.strain_p99, b3 + 0.95 * (a3 - b3), 1e-6);
  ASSERT_EQ(s.strain_p99_curve.size(), 2u);
  EXPECT_NEAR(s.strain_p99_curve[0], b3 + 0.98 * (a3 - b3), 1e-6);  // 3 values: rank 1.98
  EXPECT_NEAR(s.strain_p99_curve[1], b4 + 0.98 * (a4 - b4), 1e-6);
  EXPECT_EQ(s.error, 0.0);
  MethodResult m;
  m.sequences = {s};
  const Summary sum = summarise(m);
  EXPECT_NEAR(sum.strain_mean_percent.mean, 100 * s.strain_mean, 1e-9);
  EXPECT_NEAR(sum.strain_p99_percent.mean, 100 * s.strain_p99, 1e-9);
  ASSERT_EQ(sum.strain_p99_curve_percent.size(), 2u);
  EXPECT_NEAR(sum.strain_p99_curve_percent[1], 100 * s.strain_p99_curve[1], 1e-9);
}

// Every garment at its rest shape scaled by `factor` about the origin, moved with the data.
struct ScaledRest : Predictor {
  float factor = 1.1f;
  std::string name() const override { return "rest x 1.1"; }
  Points step(const dataset::Sequence& seq, int t, const Points&, const Points&, const Points&) override {
    Points x = factor * rest_garments(seq);
    x.rowwise() += seq.info.translation.row(t + 1);
    return x;
  }
};

TEST(Strain, AGarmentScaledByTenPercentHasTenPercentStrain) {
  const dataset::Sequence seq = sequence(2, 8);
  ScaledRest scaled;
  const SequenceResult s = score_rollout(seq, rollout(scaled, seq, 2, 4), {});
  EXPECT_NEAR(s.strain_mean, 0.1, 1e-5);
  EXPECT_NEAR(s.strain_p99, 0.1, 1e-5);
  for (double p : s.strain_p99_curve) EXPECT_NEAR(p, 0.1, 1e-5);
  scaled.factor = 1.f;  // the rest shape itself: no strain
  EXPECT_NEAR(score_rollout(seq, rollout(scaled, seq, 2, 4), {}).strain_p99, 0.0, 1e-6);
}

using testing::Diverging;

TEST(Strain, ADivergedRolloutLeavesNoNaNInTheSummary) {
  const dataset::Sequence seq = sequence(2, 10);
  Diverging d;
  const SequenceResult bad = score_rollout(seq, rollout(d, seq, 2, 5), {});
  ASSERT_EQ(bad.strain_p99_curve.size(), 5u);
  EXPECT_TRUE(std::isfinite(bad.strain_p99_curve[0]));
  EXPECT_TRUE(std::isnan(bad.strain_p99_curve[1]));
  EXPECT_TRUE(std::isnan(bad.strain_mean));
  GroundTruth gt;
  MethodResult m;
  m.sequences = {bad, score_rollout(seq, rollout(gt, seq, 2, 5), {})};
  const Summary sum = summarise(m);
  EXPECT_EQ(sum.diverged, 1);
  EXPECT_EQ(sum.strain_mean_percent.count, 1);
  EXPECT_DOUBLE_EQ(sum.strain_mean_percent.mean, 100 * m.sequences[1].strain_mean);
  EXPECT_GT(sum.strain_p99_percent.mean, 0.0);  // the synthetic cloth ripples
  ASSERT_EQ(sum.strain_p99_curve_percent.size(), 5u);
  for (double p : sum.strain_p99_curve_percent) EXPECT_TRUE(std::isfinite(p));
}

TEST(RolloutStart, AfterTheRampByDefaultAndTheFixedStartOnRequest) {
  const fs::path dir = fs::temp_directory_path() / ("layersnet_start_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  const std::string path = (dir / "s.h5").string();
  dataset::write_sequence(path, sequence(1, 12));
  EvalOptions o;
  o.start_frame = 3;
  ASSERT_TRUE(o.start_after_ramp);  // the default
  // A file without the generator's attributes: the fixed start.
  RolloutStart s = rollout_start(path, o);
  EXPECT_EQ(s.input_frame, 3);
  EXPECT_FALSE(s.after_ramp);
  EXPECT_EQ(settled_frame(path), 0);  // the stress command's default is unchanged
  {
    const hid_t f = H5Fopen(path.c_str(), H5F_ACC_RDWR, H5P_DEFAULT);
    ASSERT_GE(f, 0);
    dataset::h5::write_int_attr(f, "rest_frames", 4);
    dataset::h5::write_int_attr(f, "ramp_frames", 3);
    H5Fclose(f);
  }
  // The first predicted frame t0 + 1 is rest_frames + ramp_frames = 7.
  s = rollout_start(path, o);
  EXPECT_EQ(s.input_frame, 6);
  EXPECT_TRUE(s.after_ramp);
  o.start_after_ramp = false;
  s = rollout_start(path, o);
  EXPECT_EQ(s.input_frame, 3);
  EXPECT_FALSE(s.after_ramp);
  fs::remove_all(dir);
}

}  // namespace
}  // namespace layersnet::eval
