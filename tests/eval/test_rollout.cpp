// Rollouts, baselines and the model predictor on tiny synthetic sequences.
#include "dataset/synthetic.h"
#include "eval/evaluate.h"
#include "eval/rollout.h"
#include "eval/stress.h"
#include "run/run_dir.h"
#include "test_predictors.h"
#include "model/layersnet.h"
#include "model/params_layout.h"
#include "model/sample_input.h"
#include "run/config.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <limits>
#include <memory>
#include <random>

namespace layersnet::eval {
namespace {

using testing::sequence;

// Overwrites every garment frame with x_t = x_0 + f(t).
template <class Fn>
void move_garments(dataset::Sequence& seq, Fn shift) {
  for (int t = 0; t < seq.info.num_frames; ++t)
    for (int g = 0; g < seq.info.num_garments(); ++g) {
      const int n = seq.info.garments[g].num_vertices;
      const dataset::Points x0 = seq.garment_at(g, 0);
      auto rows = seq.frames.garments[g].middleRows(static_cast<Eigen::Index>(t) * n, n);
      rows = x0;
      rows.rowwise() += shift(t);
    }
}

TEST(Rollout, ConstantVelocityIsExactOnUniformMotion) {
  dataset::Sequence seq = sequence(2);
  move_garments(seq, [](int t) { return Eigen::RowVector3f(0.1f * t, -0.05f * t, 0.02f * t); });
  ConstantVelocity cv;
  const Rollout r = rollout(cv, seq, 2, 6);
  ASSERT_EQ(r.frames.size(), 6u);
  EXPECT_EQ(r.first_frame, 3);
  const SequenceResult s = score_rollout(seq, r, {});
  EXPECT_LT(s.error, 1e-5);
  EXPECT_EQ(s.error_curve.size(), 6u);
}

// Recorded pins: every predicted frame takes the pinned rows from the data and leaves the others
// to the method; a sequence that records none (as `simulate` builds) is left to the method.
TEST(Rollout, RecordedPinsAreTheDatasForEveryMethod) {
  dataset::Sequence seq = sequence(2);
  move_garments(seq, [](int t) { return Eigen::RowVector3f(0.02f * t * t, 0, 0); });  // accelerating
  auto& outer = seq.info.garments.back();
  outer.pin.assign(static_cast<size_t>(outer.num_vertices), 0.f);
  outer.pin[0] = outer.pin[3] = 1.f;
  const int first_outer = seq.info.garments.front().num_vertices;
  ConstantVelocity cv;
  const Rollout free = rollout(cv, seq, 2, 5), driven = rollout(cv, seq, 2, 5, true);
  for (size_t k = 0; k < driven.frames.size(); ++k) {
    const dataset::Points truth = garments_at(seq, driven.first_frame + static_cast<int>(k));
    for (Eigen::Index v = 0; v < truth.rows(); ++v) {
      const bool pinned = v == first_outer || v == first_outer + 3;
      const float off_truth = (driven.frames[k].row(v) - truth.row(v)).norm();
      if (pinned) {
        EXPECT_LT(off_truth, 1e-6f) << "frame " << k << " pinned row " << v;
      } else if (k > 0) {
        EXPECT_GT(off_truth, 1e-3f) << "frame " << k << " free row " << v;  // constant velocity lags
      }
    }
    EXPECT_GT((free.frames[k].row(first_outer) - truth.row(first_outer)).norm(), k > 0 ? 1e-3f : -1.f);
  }
  seq.info.pins_recorded = false;
  const Rollout unrecorded = rollout(cv, seq, 2, 5, true);
  for (size_t k = 0; k < unrecorded.frames.size(); ++k) EXPECT_TRUE(unrecorded.frames[k].isApprox(free.frames[k]));
}

TEST(Rollout, FollowBodyIsExactWhenTheGarmentMovesWithTheRoot) {
  dataset::Sequence seq = sequence(1);
  const dataset::Points r = seq.info.translation;
  move_garments(seq, [&](int t) { return Eigen::RowVector3f(r.row(t) - r.row(0)); });
  FollowBody fb;
  const SequenceResult s = score_rollout(seq, rollout(fb, seq, 2, 7), {});
  EXPECT_LT(s.error, 1e-5);
  // Constant velocity is not exact here (the root moves on a sine path).
  ConstantVelocity cv;
  EXPECT_GT(score_rollout(seq, rollout(cv, seq, 2, 7), {}).error, 1e-4);
}

// Records what the rollout feeds it; predicts a fixed offset from x_now.
struct Recorder : Predictor {
  std::vector<Points> seen_now, seen_prev, outputs;
  std::string name() const override { return "recorder"; }
  Points step(const dataset::Sequence&, int, const Points&, const Points& prev, const Points& now) override {
    seen_prev.push_back(prev);
    seen_now.push_back(now);
    Points x = now;
    x.array() += 0.5f;
    outputs.push_back(x);
    return x;
  }
};

TEST(Rollout, FeedsItsOwnPredictionsBackAndStartsFromGroundTruth) {
  const dataset::Sequence seq = sequence(2);
  Recorder rec;
  const Rollout r = rollout(rec, seq, 3, 100);  // clamped to T-1-t0 = 6 frames
  ASSERT_EQ(r.frames.size(), 6u);
  EXPECT_EQ(rec.seen_now[0], garments_at(seq, 3));
  EXPECT_EQ(rec.seen_prev[0], garments_at(seq, 2));
  EXPECT_EQ(rec.seen_prev[1], garments_at(seq, 3));
  for (size_t k = 1; k < rec.seen_now.size(); ++k) EXPECT_EQ(rec.seen_now[k], rec.outputs[k - 1]);
  // Input frame t0 needs t0-2 >= 0 and t0+1 <= T-1 (T = 10).
  EXPECT_THROW(rollout(rec, seq, 1, 3), std::invalid_argument);
  EXPECT_EQ(rollout(rec, seq, 8, 3).frames.size(), 1u);
  EXPECT_THROW(rollout(rec, seq, 9, 3), std::invalid_argument);
}

using testing::Diverging;

TEST(Rollout, ADivergedRolloutIsMarkedAndLeftOutOfTheSummary) {
  const dataset::Sequence seq = sequence(2);
  Diverging d;
  const Rollout r = rollout(d, seq, 2, 5);
  EXPECT_EQ(r.diverged_at, 1);
  EXPECT_EQ(d.calls, 2);  // not called again after the NaN
  ASSERT_EQ(r.frames.size(), 5u);
  EXPECT_TRUE(r.frames[4].array().isNaN().all());
  const SequenceResult s = score_rollout(seq, r, {});  // no crash on NaN queries
  EXPECT_EQ(s.error_curve[0], 0.0);
  EXPECT_TRUE(std::isnan(s.error_curve[1]));
  MethodResult m;
  m.sequences = {s, score_rollout(seq, rollout(*std::make_unique<GroundTruth>(), seq, 2, 5), {})};
  m.sequences[0].diverged_at = s.diverged_at;
  const Summary sum = summarise(m);
  EXPECT_EQ(sum.diverged, 1);
  EXPECT_EQ(sum.error_mm.count, 1);
  EXPECT_EQ(sum.error_mm.mean, 0.0);
  // NaN rows never count as collisions.
  Points nan_rows = Points::Constant(3, 3, std::numeric_limits<float>::quiet_NaN());
  EXPECT_EQ(count_body_collisions(nan_rows, seq.body_at(2), seq.info.body_faces, 5.0), 0);
  EXPECT_EQ(count_layer_collisions(nan_rows, garments_at(seq, 2), seq.info.garments[0].faces), 0);
}

TEST(Rollout, GroundTruthHasZeroErrorAndTheDataCollisionRates) {
  const dataset::Sequence seq = sequence(2);
  GroundTruth gt;
  const Rollout r = rollout(gt, seq, 2, 5);
  const SequenceResult s = score_rollout(seq, r, {});
  EXPECT_EQ(s.error, 0.0);
  EXPECT_GE(s.h_rate, 0.0);
  EXPECT_GE(s.l_rate_outer, 0.0);
  EXPECT_NEAR(s.l_rate_all, s.l_rate_outer * seq.info.garments[1].num_vertices / seq.info.total_garment_vertices(), 1e-12);
  // The concentric tubes never cross: no layer collisions. The body test has false positives
  // on this coarse capped cylinder (inner tube's top ring lies below the body's top rim,
  // whose vertex normal tilts upwards): the floor is the data's own rate, recounted here.
  EXPECT_EQ(s.l_rate_outer, 0.0);
  double h = 0;
  for (int t = 3; t < 8; ++t)
    h += static_cast<double>(count_body_collisions(garments_at(seq, t), seq.body_at(t), seq.info.body_faces, 5.0)) /
         seq.info.total_garment_vertices() / 5;
  EXPECT_NEAR(s.h_rate, h, 1e-12);
  EXPECT_GT(s.h_rate, 0.0);
}

// A replay of the data's own file scores like the ground truth; a shifted recording scores
// its shift; a recording of other garments or too few frames is refused, naming its file.
TEST(Rollout, ReplayScoresARecordingAndRefusesOneThatDoesNotMatch) {
  const std::filesystem::path dir = std::filesystem::temp_directory_path() / "layersnet_replay_test";
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir / "data");
  std::filesystem::create_directories(dir / "same");
  std::filesystem::create_directories(dir / "shifted");
  std::filesystem::create_directories(dir / "other");
  dataset::Sequence seq = sequence(2);
  dataset::write_sequence((dir / "data" / "00000.h5").string(), seq);
  dataset::write_sequence((dir / "same" / "00000.h5").string(), seq);
  dataset::Sequence shifted = seq;
  for (auto& g : shifted.frames.garments) g.col(0).array() += 0.25f;
  dataset::write_sequence((dir / "shifted" / "00000.h5").string(), shifted);
  dataset::write_sequence((dir / "other" / "00000.h5").string(), sequence(1));
  seq = dataset::read_sequence((dir / "data" / "00000.h5").string());  // info.path names the file

  Replay same("same", (dir / "same").string()), moved("shifted", (dir / "shifted").string());
  const SequenceResult s = score_rollout(seq, rollout(same, seq, 2, 5), {});
  GroundTruth gt;
  const SequenceResult g = score_rollout(seq, rollout(gt, seq, 2, 5), {});
  EXPECT_EQ(s.error, 0.0);
  EXPECT_EQ(s.h_rate, g.h_rate);
  EXPECT_NEAR(score_rollout(seq, rollout(moved, seq, 2, 5), {}).error, 0.25, 1e-5);

  Replay other("other", (dir / "other").string()), missing("missing", (dir / "none").string());
  try {
    rollout(other, seq, 2, 5);
    ADD_FAILURE() << "a recording with other garments was replayed";
  } catch (const std::exception& e) {
    EXPECT_NE(std::string(e.what()).find((dir / "other" / "00000.h5").string()), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("1 garments, not 2"), std::string::npos) << e.what();
  }
  EXPECT_THROW(rollout(missing, seq, 2, 5), std::runtime_error);
  std::filesystem::remove_all(dir);
}

// The truth, with every vertex that lies at least 0.06 m from the body (brute force over the
// body's vertices) moved by 0.5 units along x.
struct ShiftFreeCloth : Predictor {
  std::string name() const override { return "free cloth shifted"; }
  Points step(const dataset::Sequence& seq, int t, const Points&, const Points&, const Points&) override {
    Points x = garments_at(seq, t + 1);
    const Points body = seq.body_at(t + 1);
    for (Eigen::Index v = 0; v < x.rows(); ++v)
      if ((body.rowwise() - x.row(v)).rowwise().norm().minCoeff() / seq.info.scale >= 0.06) x(v, 0) += 0.5f;
    return x;
  }
};

TEST(Rollout, ErrorIsSplitByTheTruthsDistanceFromTheBody) {
  const dataset::Sequence seq = sequence(2, 8);
  ShiftFreeCloth shift;
  const SequenceResult s = score_rollout(seq, rollout(shift, seq, 2, 4), {});
  const int64_t vertex_frames = 4 * seq.info.total_garment_vertices();
  EXPECT_EQ(s.band_vertex_frames[0] + s.band_vertex_frames[1] + s.band_vertex_frames[2], vertex_frames);
  ASSERT_GT(s.band_vertex_frames[2], 0) << "the test needs free cloth";
  ASSERT_GT(s.band_vertex_frames[0] + s.band_vertex_frames[1], 0) << "the test needs cloth near the body";
  EXPECT_EQ(s.band_error[0], 0.0);
  EXPECT_EQ(s.band_error[1], 0.0);
  EXPECT_NEAR(s.band_error[2], 0.5, 1e-6);
  // The overall error is the bands' vertex-weighted mean.
  EXPECT_NEAR(s.error, 0.5 * static_cast<double>(s.band_vertex_frames[2]) / static_cast<double>(vertex_frames), 1e-6);
  MethodResult m;
  m.sequences = {s, s};
  const Summary sum = summarise(m);
  EXPECT_NEAR(sum.band_mm[2], 0.5 * s.mm(), 1e-6);
  EXPECT_NEAR(sum.band_share[0] + sum.band_share[1] + sum.band_share[2], 1.0, 1e-12);
  EXPECT_NEAR(sum.band_share[2], static_cast<double>(s.band_vertex_frames[2]) / static_cast<double>(vertex_frames), 1e-12);
}

// Rotates frame t of the body and garments of seq about the z axis through `pivot` by t * step
// radians and shifts it by t * drift: the whole scene moves rigidly, frame 0 stays.
void move_rigidly(dataset::Sequence& seq, float step, const Eigen::RowVector3f& pivot, const Eigen::RowVector3f& drift) {
  const int B = seq.info.num_body_vertices;
  const dataset::Points body0 = seq.body_at(0);
  std::vector<dataset::Points> garments0;
  for (int g = 0; g < seq.info.num_garments(); ++g) garments0.push_back(seq.garment_at(g, 0));
  for (int t = 0; t < seq.info.num_frames; ++t) {
    const Eigen::Matrix3f R = Eigen::AngleAxisf(step * static_cast<float>(t), Eigen::Vector3f::UnitZ()).toRotationMatrix();
    const auto move = [&](const dataset::Points& x) {
      dataset::Points y = ((x.rowwise() - pivot) * R.transpose()).rowwise() + (pivot + static_cast<float>(t) * drift);
      return y;
    };
    seq.frames.body.middleRows(static_cast<Eigen::Index>(t) * B, B) = move(body0);
    for (int g = 0; g < seq.info.num_garments(); ++g) {
      const int n = seq.info.garments[g].num_vertices;
      seq.frames.garments[g].middleRows(static_cast<Eigen::Index>(t) * n, n) = move(garments0[g]);
    }
  }
}

TEST(Rollout, SkinningCarriesAGarmentWithARigidlyTurningBody) {
  dataset::Sequence seq = sequence(2, 12);
  move_rigidly(seq, 0.15f, Eigen::RowVector3f(0.3f, -0.2f, 0.f), Eigen::RowVector3f(0.05f, 0.02f, 0.01f));
  SkinnedToBody skinned;
  const SequenceResult s = score_rollout(seq, rollout(skinned, seq, 2, 9), {});
  EXPECT_LT(s.error, 1e-4) << "skinning must carry a garment exactly under a rigid motion";
  // Translation-only skinning and follow-the-body cannot follow the turn.
  SkinnedToBody translated(false);
  EXPECT_GT(score_rollout(seq, rollout(translated, seq, 2, 9), {}).error, 0.1);
  FollowBody fb;
  EXPECT_GT(score_rollout(seq, rollout(fb, seq, 2, 9), {}).error, 0.1);
}

TEST(Rollout, SkinningBindsAtTheRolloutsFirstInputFrame) {
  // The garment moves relative to the body before t0 and rigidly with it after: a binding made
  // at t0 is exact, one made at frame 0 would not be.
  dataset::Sequence seq = sequence(1, 12);
  move_rigidly(seq, 0.1f, Eigen::RowVector3f::Zero(), Eigen::RowVector3f::Zero());
  const int n = seq.info.garments[0].num_vertices;
  for (int t = 0; t < 5; ++t) seq.frames.garments[0].middleRows(static_cast<Eigen::Index>(t) * n, n).col(2).array() += 0.3f * static_cast<float>(5 - t);
  SkinnedToBody skinned;
  EXPECT_LT(score_rollout(seq, rollout(skinned, seq, 5, 6), {}).error, 1e-4);
  EXPECT_EQ(skinned.name(), "skinned to the body");
}

TEST(Rollout, BodyFramesAreOrthonormalAndTurnWithTheBody) {
  const dataset::Sequence seq = sequence(1, 4);
  dataset::BodyTopology neighbour;
  neighbour.tangent_neighbour.resize(static_cast<size_t>(seq.info.num_body_vertices));
  for (Eigen::Index f = 0; f < seq.info.body_faces.rows(); ++f)
    for (int k = 0; k < 3; ++k)
      neighbour.tangent_neighbour[static_cast<size_t>(seq.info.body_faces(f, k))] = seq.info.body_faces(f, (k + 1) % 3);
  const dataset::Points body = seq.body_at(0);
  const auto F = dataset::body_frames(body, seq.info.body_faces, neighbour);
  const Eigen::Matrix3f R = Eigen::AngleAxisf(0.7f, Eigen::Vector3f(1, 2, 3).normalized()).toRotationMatrix();
  const dataset::Points turned = body * R.transpose();
  const auto G = dataset::body_frames(turned, seq.info.body_faces, neighbour);
  for (Eigen::Index i = 0; i < body.rows(); ++i) {
    const Eigen::Map<const Eigen::Matrix3f> f(F.row(i).data()), g(G.row(i).data());
    EXPECT_LT((f.transpose() * f - Eigen::Matrix3f::Identity()).norm(), 1e-5f) << i;
    EXPECT_LT((R * f - g).norm(), 1e-4f) << i;
  }
}

TEST(Rollout, PostProcessingIsTheSameForABaselineAsForTheModel) {
  // The constraints pull a stretched prediction back; PostProcessed applies exactly what the
  // network's rollout applies (make_cloth_constraints + apply with the frame before).
  const dataset::Sequence seq = sequence(2, 8);
  EvalConfig settings;
  settings.constraints = true;
  settings.strain_limit = 0.05;
  settings.body_friction = 0.5;
  struct Stretch : Predictor {
    std::string name() const override { return "stretch"; }
    Points step(const dataset::Sequence& s, int t, const Points&, const Points&, const Points&) override {
      return 1.3f * garments_at(s, t + 1);
    }
  };
  PostProcessed pp(std::make_unique<Stretch>(), settings);
  EXPECT_EQ(pp.name(), "[constrained] stretch");
  const Rollout r = rollout(pp, seq, 2, 4);
  Stretch bare;
  const Rollout b = rollout(bare, seq, 2, 4);
  // Replay the same step by hand through the network's road.
  const auto c = make_cloth_constraints(seq, settings);
  Points x = 1.3f * garments_at(seq, 3);
  c->apply(seq.body_at(3), x, seq.body_at(2), garments_at(seq, 2));
  EXPECT_EQ((r.frames[0] - x).cwiseAbs().maxCoeff(), 0.f);
  const GarmentEdges edges = garment_edges(seq);
  const auto strain = [&](const Points& p) { const auto e = edge_strains(edges, p); return *std::max_element(e.begin(), e.end()); };
  EXPECT_GT(strain(b.frames[0]), 0.2);
  EXPECT_LT(strain(r.frames[0]), strain(b.frames[0]));
}

TEST(Rollout, CrumpleIsZeroForAFlatSheetAndGrowsWithItsFolds) {
  dataset::GarmentLayout L;
  L.offsets = {0, 6};
  L.types = {"sheet"};
  dataset::Faces f(4, 3);
  f << 0, 1, 4, 0, 4, 3, 1, 2, 5, 1, 5, 4;  // a 3 x 2 grid, counter-clockwise
  L.faces = {f};
  const FacePairs pairs = adjacent_face_pairs(L);
  ASSERT_EQ(pairs.first.size(), 3u);  // the three interior edges
  Points flat(6, 3);
  flat << 0, 0, 0, 1, 0, 0, 2, 0, 0, 0, 1, 0, 1, 1, 0, 2, 1, 0;
  for (double a : dihedral_angles_deg(pairs, flat)) EXPECT_NEAR(a, 0.0, 1e-9);
  Points folded = flat;  // the right column lifted: a 45 degree fold along x = 1
  folded(2, 2) = 1;
  folded(5, 2) = 1;
  const auto angles = dihedral_angles_deg(pairs, folded);
  ASSERT_EQ(angles.size(), 3u);
  EXPECT_NEAR(*std::max_element(angles.begin(), angles.end()), 45.0, 1e-6);
  // A degenerate triangle is skipped, not counted as flat or folded.
  Points collapsed = flat;
  collapsed.row(4) = collapsed.row(1);
  EXPECT_LT(dihedral_angles_deg(pairs, collapsed).size(), 3u);
}

TEST(Rollout, CrumpleOfTheGroundTruthIsScoredAndMarkedAtTheMark) {
  const dataset::Sequence seq = sequence(2, 12);
  GroundTruth gt;
  const SequenceResult s = score_rollout(seq, rollout(gt, seq, 2, 9), {}, 4);
  ASSERT_EQ(s.dihedral_curve.size(), 9u);
  EXPECT_EQ(s.mark, 4);
  EXPECT_EQ(s.dihedral_at_mark, s.dihedral_curve[3]);
  EXPECT_GT(s.dihedral_mean, 0.0);  // tubes bend around the body
  EXPECT_EQ(s.error_to_mark, 0.0);
  // A mark beyond the rollout clamps to its last frame.
  EXPECT_EQ(score_rollout(seq, rollout(gt, seq, 2, 3), {}, 36).mark, 3);
}

TEST(Rollout, ComparisonsPairTheSamePostProcessingAndGivePerSequenceRatios) {
  const auto result = [](std::string name, std::string kind, bool post, std::vector<double> errors) {
    MethodResult m;
    m.name = std::move(name);
    m.kind = std::move(kind);
    m.post_processed = post;
    for (size_t i = 0; i < errors.size(); ++i) {
      SequenceResult s;
      s.id = "0000" + std::to_string(i);
      s.scale = 1000;  // 1 mm per unit
      s.error = errors[i];
      m.sequences.push_back(s);
    }
    return m;
  };
  const std::vector<MethodResult> methods = {
      result("net", "model", false, {1, 2, 3}), result("[constrained] net", "model", true, {1, 1, 1}),
      result("follow", "baseline", false, {2, 4, 3}), result("skin", "baseline", false, {4, 4, 4}),
      result("[constrained] follow", "baseline", true, {4, 2, 1})};
  const auto c = compare_with_baselines(methods);
  ASSERT_EQ(c.size(), 3u);
  EXPECT_EQ(c[0].baseline, "follow");
  EXPECT_TRUE(c[0].best_baseline);
  EXPECT_FALSE(c[1].best_baseline);
  EXPECT_NEAR(c[0].ratio_of_means, 2.0 / 3.0, 1e-12);
  EXPECT_NEAR(c[0].mean_ratio, (0.5 + 0.5 + 1.0) / 3, 1e-12);
  EXPECT_NEAR(c[0].median_ratio, 0.5, 1e-12);
  EXPECT_EQ(c[0].worst_id, "00002");
  EXPECT_NEAR(c[0].worst_ratio, 1.0, 1e-12);
  // The post-processed model meets the post-processed baseline only.
  EXPECT_EQ(c[2].model, "[constrained] net");
  EXPECT_EQ(c[2].baseline, "[constrained] follow");
  EXPECT_TRUE(c[2].best_baseline);
  EXPECT_NEAR(c[2].worst_ratio, 1.0, 1e-12);
  EXPECT_EQ(c[2].worst_id, "00002");
}

TEST(Rollout, StatsRoundTripThroughCheckpointNames) {
  dataset::NormalisationStats st;
  st.velocity.mean = Eigen::Vector3d(1, 2, 3);
  st.root_acceleration.std = Eigen::Vector3d(4, 5, 6);
  st.position.count = 17;
  const dataset::NormalisationStats back = stats_from_arrays(stats_to_arrays(st), "round trip");
  EXPECT_EQ(back.velocity.mean, st.velocity.mean);
  EXPECT_EQ(back.root_acceleration.std, st.root_acceleration.std);
  EXPECT_EQ(back.position.count, 17);
  try {
    stats_from_arrays({{"position.mean", {0, 0, 0}}}, "partial.h5");
    ADD_FAILURE() << "partial statistics were accepted";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("partial.h5: /stats/position.std"), std::string::npos) << e.what();
  }
  // The underscore spelling is read too.
  std::map<std::string, std::vector<double>> underscored;
  for (const auto& [k, v] : stats_to_arrays(st)) underscored[k.substr(0, k.find('.')) + "_" + k.substr(k.find('.') + 1)] = v;
  EXPECT_EQ(stats_from_arrays(underscored, "underscored").velocity.mean, st.velocity.mean);
}

TEST(Rollout, ModelPredictorFirstStepEqualsADirectForward) {
  const dataset::Sequence seq = sequence(2);
  Config c = load_config({std::string(LAYERSNET_SOURCE_DIR) + "/configs/tiny.toml"});
  dataset::NormalisationStats st;  // identity normalisation
  ad::ParamStore<float> ps;
  model::register_params(ps, c.model);
  model::init_params(ps, c.model, 3);
  // Direct: the dataset sample of the ground truth at t = 2.
  const auto opt = model::sample_options_for(c.model);
  const auto sample = dataset::build_sample(seq.info, seq.frames, 2, st, nullptr, opt);
  const auto input = model::model_input_from_sample(sample, st, c.model);
  ad::Tape<float> tape;
  ad::ParamStore<float> ps_copy;
  model::register_params(ps_copy, c.model);
  std::copy(ps.values().begin(), ps.values().end(), ps_copy.values().begin());
  const auto pred = model::forward(tape, ps_copy, c.model, input);
  Points direct = pred.vertex.val().leftCols(3);
  direct.rowwise() += sample.root_translation_next.transpose();

  ModelPredictor mp("tiny", c, std::move(ps), st);
  const Rollout r = rollout(mp, seq, 2, 4);
  ASSERT_EQ(r.frames.size(), 4u);
  EXPECT_LT((r.frames[0] - direct).cwiseAbs().maxCoeff(), 1e-5f);
  for (const auto& f : r.frames) EXPECT_TRUE(f.allFinite());
  EXPECT_GT(median_ms_per_frame(mp, seq, 2, 3, 1), 0.0);
}

// The physics-step baseline is what a "physics" model with a zero output predicts (the output
// layer starts at zero), frame by frame of its own rollout; and it is neither skinning nor
// constant velocity.
TEST(Rollout, PhysicsStepBaselineIsTheZeroOutputPhysicsModel) {
  const dataset::Sequence seq = sequence(2);
  Config c = load_config({std::string(LAYERSNET_SOURCE_DIR) + "/configs/tiny.toml"}, {"model.velocity_base=physics"});
  dataset::NormalisationStats st;
  ad::ParamStore<float> ps;
  model::register_params(ps, c.model);
  model::init_params(ps, c.model, 3);
  ModelPredictor zero("zero", c, std::move(ps), st);
  PhysicsStep physics;
  ConstantVelocity constant;
  SkinnedToBody skinned;
  const Rollout a = rollout(zero, seq, 2, 4), b = rollout(physics, seq, 2, 4), k = rollout(constant, seq, 2, 4),
                sk = rollout(skinned, seq, 2, 4);
  ASSERT_EQ(a.frames.size(), 4u);
  ASSERT_EQ(b.frames.size(), 4u);
  for (size_t f = 0; f < 4; ++f) {
    EXPECT_LT((a.frames[f] - b.frames[f]).cwiseAbs().maxCoeff(), 1e-4f) << "frame " << f;
    EXPECT_GT((b.frames[f] - k.frames[f]).cwiseAbs().maxCoeff(), 1e-3f) << "frame " << f;
    EXPECT_GT((b.frames[f] - sk.frames[f]).cwiseAbs().maxCoeff(), 1e-3f) << "frame " << f;
    EXPECT_TRUE(b.frames[f].allFinite());
  }
}

// Built from a model's config, the baseline is that model's step: a zero-output model on a softer
// step rolls out what PhysicsStep(its config) does, and not what the default step does.
TEST(Rollout, PhysicsStepBaselineTakesTheModelsStepSettings) {
  const dataset::Sequence seq = sequence(2);
  Config c = load_config({std::string(LAYERSNET_SOURCE_DIR) + "/configs/tiny.toml"},
                         {"model.velocity_base=physics", "model.physics_step_bending=0.25"});
  ad::ParamStore<float> ps;
  model::register_params(ps, c.model);
  model::init_params(ps, c.model, 3);
  ModelPredictor zero("zero, softer step", c, std::move(ps), dataset::NormalisationStats{});
  PhysicsStep own(c.model), defaults;
  const Rollout a = rollout(zero, seq, 2, 4), b = rollout(own, seq, 2, 4), d = rollout(defaults, seq, 2, 4);
  float apart = 0;
  for (size_t f = 0; f < 4; ++f) {
    EXPECT_LT((a.frames[f] - b.frames[f]).cwiseAbs().maxCoeff(), 1e-4f) << "frame " << f;
    apart = std::max(apart, (b.frames[f] - d.frames[f]).cwiseAbs().maxCoeff());
  }
  EXPECT_GT(apart, 1e-3f) << "the bending factor should move the step";
}

// The tiny model on the physics step with a non-zero correction (random output weights), under
// one rollout setting "eval.KEY=VALUE".
std::unique_ptr<ModelPredictor> corrected_step_model(const std::string& setting) {
  Config c = load_config({std::string(LAYERSNET_SOURCE_DIR) + "/configs/tiny.toml"}, {"model.velocity_base=physics", setting});
  ad::ParamStore<float> ps;
  model::register_params(ps, c.model);
  model::init_params(ps, c.model, 3);
  std::mt19937_64 rng(5);
  std::normal_distribution<float> normal(0, 0.3f);
  for (auto& x : ps.value(ps.index_of("decoder.proj.2.weight"))) x = normal(rng);
  return std::make_unique<ModelPredictor>(setting, c, std::move(ps), dataset::NormalisationStats{});
}

// eval.correction_scale scales the network's correction of the physics step: 0 rolls out the step
// itself, and one frame from the same input at 0.5 lies halfway between the frames at 0 and 1.
TEST(Rollout, CorrectionScaleScalesTheNetworksCorrectionOfTheStep) {
  const dataset::Sequence seq = sequence(2);
  auto predictor = [&](const std::string& scale) { return corrected_step_model("eval.correction_scale=" + scale); };
  PhysicsStep physics;
  const Rollout step = rollout(physics, seq, 2, 3);
  const Rollout r0 = rollout(*predictor("0"), seq, 2, 3), r1 = rollout(*predictor("1"), seq, 2, 1),
                half = rollout(*predictor("0.5"), seq, 2, 1);
  for (size_t f = 0; f < 3; ++f) EXPECT_LT((r0.frames[f] - step.frames[f]).cwiseAbs().maxCoeff(), 1e-4f) << f;
  const float moved = (r1.frames[0] - r0.frames[0]).cwiseAbs().maxCoeff();
  EXPECT_GT(moved, 1e-3f);
  EXPECT_LT((half.frames[0] - 0.5f * (r0.frames[0] + r1.frames[0])).cwiseAbs().maxCoeff(), 1e-4f * std::max(1.0f, moved));
}

// At eval.correction_scale = 0 the network is not run: weights that are all NaN still roll out
// the step itself, where any other scale spreads the NaN.
TEST(Rollout, CorrectionScaleZeroRunsNoNetwork) {
  const dataset::Sequence seq = sequence(2);
  auto nan_model = [&](const std::string& scale) {
    Config c = load_config({std::string(LAYERSNET_SOURCE_DIR) + "/configs/tiny.toml"},
                           {"model.velocity_base=physics", "eval.correction_scale=" + scale});
    ad::ParamStore<float> ps;
    model::register_params(ps, c.model);
    std::ranges::fill(ps.values(), std::numeric_limits<float>::quiet_NaN());
    return std::make_unique<ModelPredictor>("NaN weights", c, std::move(ps), dataset::NormalisationStats{});
  };
  PhysicsStep physics;
  const Rollout step = rollout(physics, seq, 2, 3), none = rollout(*nan_model("0"), seq, 2, 3);
  for (size_t f = 0; f < 3; ++f) {
    ASSERT_TRUE(none.frames[f].allFinite()) << f;
    EXPECT_LT((none.frames[f] - step.frames[f]).cwiseAbs().maxCoeff(), 1e-4f) << f;
  }
  EXPECT_FALSE(rollout(*nan_model("0.5"), seq, 2, 1).frames[0].allFinite());
}

// eval.mirror_average makes the network symmetric under mirrors as the cloth is: its rollout of
// a scene's mirror image is the mirror image of its rollout, where the plain network's is not;
// and its first frame is the mean of the plain network's prediction and the image of its
// prediction on the image.
TEST(Rollout, MirrorAverageMakesTheNetworkMirrorSymmetric) {
  const dataset::Sequence seq = sequence(2);
  dataset::Sequence image = seq;
  dataset::mirror(image);
  auto predictor = [&](bool average) {
    return corrected_step_model(std::string("eval.mirror_average=") + (average ? "true" : "false"));
  };
  const Eigen::Matrix3f M = Eigen::Vector3f(-1.f, 1.f, 1.f).asDiagonal();
  const auto asymmetry = [&](bool average) {
    const Rollout a = rollout(*predictor(average), seq, 2, 3), b = rollout(*predictor(average), image, 2, 3);
    float worst = 0;
    for (size_t f = 0; f < 3; ++f) worst = std::max(worst, (b.frames[f] - a.frames[f] * M).cwiseAbs().maxCoeff());
    return worst;
  };
  EXPECT_GT(asymmetry(false), 1e-3f);  // the plain network tells a scene from its image
  EXPECT_LT(asymmetry(true), 1e-4f);
  const Rollout plain = rollout(*predictor(false), seq, 2, 1), plain_image = rollout(*predictor(false), image, 2, 1),
                averaged = rollout(*predictor(true), seq, 2, 1);
  EXPECT_LT((averaged.frames[0] - 0.5f * (plain.frames[0] + plain_image.frames[0] * M)).cwiseAbs().maxCoeff(), 1e-5f);
}

// The projection of a model's wind movement on Blender's: all of it, half, none, against it.
TEST(Rollout, WindShareProjectsTheModelsWindMovementOnBlenders) {
  std::mt19937 rng(5);
  std::normal_distribution<float> noise(0.0f, 1.0f);
  const auto random_frames = [&](int n) {
    std::vector<Points> frames;
    for (int k = 0; k < n; ++k) {
      Points p(7, 3);
      for (Eigen::Index i = 0; i < p.size(); ++i) p.data()[i] = noise(rng);
      frames.push_back(p);
    }
    return frames;
  };
  const std::vector<Points> twin = random_frames(4), truth = random_frames(4), scaled = random_frames(4);
  const auto moved_by = [&](float along, const std::vector<Points>& across) {
    std::vector<Points> out;
    for (std::size_t k = 0; k < twin.size(); ++k) out.push_back(scaled[k] + along * (truth[k] - twin[k]) + across[k]);
    return out;
  };
  const std::vector<Points> none(4, Points::Zero(7, 3));
  EXPECT_NEAR(wind_share(scaled, moved_by(1.0f, none), twin, truth), 1.0, 1e-6);
  EXPECT_NEAR(wind_share(scaled, moved_by(0.5f, none), twin, truth), 0.5, 1e-6);
  EXPECT_NEAR(wind_share(scaled, moved_by(-1.0f, none), twin, truth), -1.0, 1e-6);
  // A movement across Blender's adds nothing: g kept in the xy plane, the model moving by g turned
  // a quarter about z.
  std::vector<Points> flat_twin = twin, across;
  for (std::size_t k = 0; k < twin.size(); ++k) {
    flat_twin[k].col(2) = truth[k].col(2);
    const Points g = truth[k] - flat_twin[k];
    Points quarter = Points::Zero(7, 3);
    quarter.col(0) = -g.col(1);
    quarter.col(1) = g.col(0);
    across.push_back(scaled[k] + 3.0f * quarter);
  }
  EXPECT_NEAR(wind_share(scaled, across, flat_twin, truth), 0.0, 1e-6);
  EXPECT_TRUE(std::isnan(wind_share(scaled, moved_by(1.0f, none), truth, truth)));  // Blender's cloth did not move
  EXPECT_THROW(wind_share(scaled, random_frames(3), twin, truth), std::invalid_argument);
}

}  // namespace
}  // namespace layersnet::eval
