// Stability at the extremes, short CI version. The full version on the
// default model is scripts/extremes.sh (`layersnet stress` with 600 frames).
//
// One tiny model (configs/tiny.toml) trained for one epoch on a synthetic data set serves
// every test: stress scenes (ping-pong, speed, constant wind), the distance bound with known
// predictors, 100-frame rollouts at winds 0/400/2000 and 5x body speed, degenerate inputs
// (finite outputs and gradients), float32 vs float64, 10x learning rate, and the CLI.
#include "dataset/manifest.h"
#include "dataset/stats.h"
#include "dataset/synthetic.h"
#include "dataset/wind.h"
#include "eval/evaluate.h"
#include "eval/metrics.h"
#include "eval/rollout.h"
#include "eval/stress.h"
#include "eval/tether.h"
#include "dataset/sample.h"
#include "losses/losses.h"
#include "losses/sample_loss_input.h"
#include "model/layersnet.h"
#include "model/params_layout.h"
#include "model/sample_input.h"
#include "run/checkpoint.h"
#include "run/run_dir.h"
#include "train/trainer.h"

#include "tests/eval/cli_test_util.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <sys/wait.h>

#include <array>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>

namespace layersnet::eval {
namespace {

namespace fs = std::filesystem;

dataset::SyntheticOptions synthetic_options() {
  dataset::SyntheticOptions o;
  o.garments = 2;
  o.frames = 12;
  o.rings = 4;
  o.segments = 12;
  o.body_rings = 4;
  o.body_segments = 12;
  o.wind = true;
  return o;
}

Config tiny_config(const std::string& data, std::vector<std::string> overrides = {}) {
  overrides.insert(overrides.begin(), {"data.dataset=" + data, "data.first_frame=2", "data.max_frames=0",
                                       "train.epochs=1", "train.threads=2"});
  return load_config({std::string(LAYERSNET_SOURCE_DIR) + "/configs/tiny.toml"}, overrides);
}

class Extremes : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    root_ = fs::temp_directory_path() / ("layersnet_extremes_" + std::to_string(::getpid()));
    fs::remove_all(root_);
    const auto manifest = dataset::write_synthetic_dataset((root_ / "data").string(), 4, 1, 1, synthetic_options());
    dataset::write_stats(manifest.stats_path(), dataset::compute_stats(manifest));
    TrainOptions o;
    o.run_dir = (root_ / "base").string();
    o.log = &log_;
    train(tiny_config((root_ / "data").string()), o);
    const auto all = list_checkpoints(o.run_dir);
    ASSERT_FALSE(all.empty()) << log_.str();
    checkpoint_ = all.back();
    model_ = std::make_unique<LoadedModel>(load_model(checkpoint_));
    stats_ = stats_from_arrays(model_->checkpoint.stats, "model");
    source_ = dataset::make_synthetic_sequence(synthetic_options());
  }
  static void TearDownTestSuite() {
    model_.reset();
    if (!std::getenv("LAYERSNET_EXTREMES_TEST_KEEP")) fs::remove_all(root_);
  }
  static fs::path root_;
  static std::ostringstream log_;
  static std::string checkpoint_;
  static std::unique_ptr<LoadedModel> model_;
  static dataset::NormalisationStats stats_;
  static dataset::Sequence source_;
};
fs::path Extremes::root_;
std::ostringstream Extremes::log_;
std::string Extremes::checkpoint_;
std::unique_ptr<LoadedModel> Extremes::model_;
dataset::NormalisationStats Extremes::stats_;
dataset::Sequence Extremes::source_;

// ---- stress scenes and the bound ------------------------------------------------------------

TEST(StressScene, PingPongsAndScalesTheBodyAndHoldsTheWind) {
  const dataset::Sequence src = dataset::make_synthetic_sequence(synthetic_options());  // T = 12
  StressScene s;
  s.frames = 40;
  s.speed = 2.5;
  s.wind_strength = 2000;
  const dataset::Sequence seq = make_stress_sequence(src, s);
  ASSERT_EQ(seq.info.num_frames, 40);
  const int B = src.info.num_body_vertices;
  ASSERT_EQ(seq.frames.body.rows(), 40 * B);
  // Frame 1 plays source time 2.5: halfway between source frames 2 and 3.
  const dataset::Points mid = 0.5f * (src.body_at(2) + src.body_at(3));
  EXPECT_LT((seq.body_at(1) - mid).cwiseAbs().maxCoeff(), 1e-5f);
  // Frame 6 plays 15 = 11 + 4, i.e. source frame 11 - 4 = 7 on the way back.
  EXPECT_LT((seq.body_at(6) - src.body_at(7)).cwiseAbs().maxCoeff(), 1e-5f);
  EXPECT_LT((seq.info.translation.row(6) - src.info.translation.row(7)).cwiseAbs().maxCoeff(), 1e-5f);
  EXPECT_LT((seq.garment_at(1, 6) - src.garment_at(1, 7)).cwiseAbs().maxCoeff(), 1e-5f);
  // Constant wind along a unit quaternion.
  ASSERT_TRUE(seq.info.has_wind);
  for (int t = 0; t < 40; ++t) {
    EXPECT_EQ(seq.info.wind_strength[t], 2000.f);
    EXPECT_NEAR(seq.info.wind_rotation.row(t).norm(), 1.f, 1e-5f);
  }
  // Source wind when S < 0.
  const dataset::Sequence own = make_stress_sequence(src, {20, 1.0, -1.0});
  for (int t = 0; t < 12; ++t) EXPECT_EQ(own.info.wind_strength[t], src.info.wind_strength[t]);
  EXPECT_EQ(own.info.wind_strength[13], src.info.wind_strength[9]);  // 13 -> 22 - 13 = 9
  // Looping from f0 = 4: frame 0 is source 4, frame 7 source 11, frame 8 back at source 10.
  const dataset::Sequence looped = make_stress_sequence(src, {20, 1.0, -1.0, 4});
  EXPECT_EQ(looped.body_at(0), src.body_at(4));
  EXPECT_EQ(looped.body_at(7), src.body_at(11));
  EXPECT_EQ(looped.body_at(8), src.body_at(10));
  EXPECT_EQ(looped.garment_at(0, 0), src.garment_at(0, 4));
  EXPECT_THROW(make_stress_sequence(src, {20, 1.0, 0.0, 11}), std::invalid_argument);
  EXPECT_THROW(make_stress_sequence(src, {3, 1.0, 0.0}), std::invalid_argument);
  // Top speed: computed without the sequence equals the built sequence's; the factor for 5x
  // the top speed is >= 5 and reaches 5x, or (this 12-frame source cannot) is at least as fast
  // as any factor up to 20.
  const dataset::Sequence fast = make_stress_sequence(src, {40, 2.5, 0.0});
  double top = 0;
  for (int t = 1; t < 40; ++t) top = std::max(top, static_cast<double>((fast.body_at(t) - fast.body_at(t - 1)).rowwise().norm().maxCoeff()));
  EXPECT_NEAR(body_top_speed(src, 0, 2.5, 40), top, 1e-5);
  const double s5 = speed_factor_for_top_speed(src, 0, 5.0, 40);
  EXPECT_GE(s5, 5.0);
  double reachable = 0;
  for (double f = 5; f <= 20; f += 0.25) reachable = std::max(reachable, body_top_speed(src, 0, f, 40));
  EXPECT_GE(body_top_speed(src, 0, s5, 40),
            std::min(5.0 * body_top_speed(src, 0, 1.0, 40), reachable) * (1 - 1e-6));
  EXPECT_THROW(make_stress_sequence(src, {10, 0.0, 0.0}), std::invalid_argument);
}

TEST(StressScene, GraphDiameterBoundsTheGarmentsEuclideanDiameter) {
  const dataset::Sequence src = dataset::make_synthetic_sequence(synthetic_options());
  const std::vector<double> d = garment_graph_diameters(src), b = garment_distance_bounds(src);
  ASSERT_EQ(d.size(), 2u);
  const dataset::Points rest = rest_garments(src);
  Eigen::Index offset = 0;
  for (int g = 0; g < 2; ++g) {
    const int n = src.info.garments[g].num_vertices;
    const dataset::Points x = rest.middleRows(offset, n);
    offset += n;
    double euclid = 0;
    for (int i = 0; i < x.rows(); ++i)
      for (int j = 0; j < x.rows(); ++j) euclid = std::max(euclid, static_cast<double>((x.row(i) - x.row(j)).norm()));
    EXPECT_GE(d[g], euclid * (1 - 1e-6)) << "garment " << g;
    EXPECT_LT(d[g], 2 * euclid) << "garment " << g;  // a tube: about (half circumference + height)
    EXPECT_GT(b[g], kStretchAllowance * d[g] - 1e-9);
  }
}

// x_{t+1} = x_t + drift: leaves any bound eventually.
struct Drifting : Predictor {
  std::string name() const override { return "drift"; }
  Points step(const dataset::Sequence&, int, const Points&, const Points&, const Points& now) override {
    Points x = now;
    x.col(0).array() += 0.5f;
    return x;
  }
};

TEST(StressScene, TheBoundPassesClothCarriedByTheBodyAndCatchesDrift) {
  const dataset::Sequence src = dataset::make_synthetic_sequence(synthetic_options());
  const double limit = kStrainAllowance * data_strain(src, 0).p99;
  FollowBody follow;
  for (double speed : {1.0, 5.0}) {
    const StressResult r = stress_rollout(follow, src, {120, speed, 2000}, "follow", limit);
    EXPECT_TRUE(r.passed()) << "speed " << speed << " ratio " << r.max_bound_ratio;
    EXPECT_EQ(r.frames, 117);
    EXPECT_LT(r.max_bound_ratio, 0.5);
    EXPECT_GT(r.max_body_speed, 0.0);
  }
  // The data itself stays well inside the bound.
  EXPECT_LT(data_bound_ratio(src, 0), 0.5);
  EXPECT_GT(data_bound_ratio(src, 0), 0.0);
  Drifting drift;
  const StressResult r = stress_rollout(drift, src, {120, 1.0, 0}, "drift", limit);
  EXPECT_TRUE(r.finite);
  EXPECT_FALSE(r.passed());
  // Reaches the bound (a few units) after roughly bound / 0.5 frames.
  EXPECT_GT(r.first_bad_frame, 0);
  EXPECT_LT(r.first_bad_frame, 60);
  EXPECT_NEAR(r.max_vertex_speed, 0.5, 1e-4);
  // The per-frame trace tells a rigid drift from stretching: the nearest vertex leaves the
  // body, edges keep the length they had at the start.
  ASSERT_EQ(r.bound_ratio_per_frame.size(), static_cast<size_t>(r.frames));
  ASSERT_EQ(r.nearest_per_frame.size(), static_cast<size_t>(r.frames));
  ASSERT_EQ(r.edge_stretch_per_frame.size(), static_cast<size_t>(r.frames));
  EXPECT_DOUBLE_EQ(*std::max_element(r.bound_ratio_per_frame.begin(), r.bound_ratio_per_frame.end()), r.max_bound_ratio);
  EXPECT_GT(r.nearest_per_frame.back(), r.nearest_per_frame.front() + 20);  // 58 units of drift
  EXPECT_NEAR(r.edge_stretch_per_frame.back(), r.edge_stretch_per_frame.front(), 1e-3);
}

TEST(StressScene, EdgeStretchIsLengthOverRestLength) {
  const dataset::Sequence src = dataset::make_synthetic_sequence(synthetic_options());
  const GarmentEdges edges = garment_edges(src);
  ASSERT_FALSE(edges.rows.empty());
  int faces = 0;
  for (const auto& g : src.info.garments) faces += g.num_faces();
  EXPECT_LT(edges.rows.size(), static_cast<size_t>(3 * faces));  // shared edges counted once
  const dataset::Points rest = rest_garments(src);
  EXPECT_NEAR(max_edge_stretch(edges, rest), 1.0, 1e-5);
  EXPECT_NEAR(max_edge_stretch(edges, dataset::Points(rest * 3.0f)), 3.0, 1e-5);
  dataset::Points pulled = rest;
  pulled.row(edges.rows[0].second) += 2.0f * (rest.row(edges.rows[0].second) - rest.row(edges.rows[0].first));
  EXPECT_GE(max_edge_stretch(edges, pulled), 3.0 - 1e-5);
}

// The ground truth of frame t + 1, every garment scaled by 3 about its own centroid: each
// edge 3x its real length (strain about 2), the garment still around the body.
struct Stretched3x : Predictor {
  std::string name() const override { return "stretched 3x"; }
  Points step(const dataset::Sequence& seq, int t, const Points&, const Points&, const Points&) override {
    Points x = garments_at(seq, t + 1);
    Eigen::Index row = 0;
    for (const auto& g : seq.info.garments) {
      auto part = x.middleRows(row, g.num_vertices);
      const Eigen::RowVector3f centre = part.colwise().mean();
      part = ((part.rowwise() - centre) * 3.0f).rowwise() + centre;
      row += g.num_vertices;
    }
    return x;
  }
};

TEST(StressScene, AGarmentStretched3xFailsTheStrainLimitWithinTheDistanceBound) {
  const dataset::Sequence src = dataset::make_synthetic_sequence(synthetic_options());
  const StrainExtremes data = data_strain(src, 0);
  const double limit = kStrainAllowance * data.p99;
  ASSERT_LT(limit, 1.0);  // a small ripple: far below a 3x stretch
  Stretched3x stretched;
  const StressResult r = stress_rollout(stretched, src, {60, 1.0, 0}, "stretched", limit);
  ASSERT_EQ(r.frames, 57);
  EXPECT_TRUE(r.finite);
  EXPECT_TRUE(r.within_bound()) << "max dist / bound " << r.max_bound_ratio;
  EXPECT_FALSE(r.within_strain());
  EXPECT_FALSE(r.passed());
  EXPECT_EQ(r.first_torn_frame, 0);
  EXPECT_EQ(r.first_bad_frame, 0);
  EXPECT_DOUBLE_EQ(r.strain_limit, limit);
  EXPECT_NEAR(r.max_strain_p99, 2.0, 3 * data.max + 1e-4);  // |3 (1 + e) - 1| for real strain e
  ASSERT_EQ(r.strain_p99_per_frame.size(), 57u);
  ASSERT_EQ(r.strain_max_per_frame.size(), 57u);
  for (size_t k = 0; k < 57; ++k) {
    EXPECT_GT(r.strain_p99_per_frame[k], limit) << "frame " << k;
    EXPECT_GE(r.strain_max_per_frame[k], r.strain_p99_per_frame[k]) << "frame " << k;
  }
}

TEST(StressScene, TheGroundTruthPassesTheStrainLimit) {
  const dataset::Sequence src = dataset::make_synthetic_sequence(synthetic_options());
  const StrainExtremes data = data_strain(src, 0);
  EXPECT_GT(data.p99, 0.0);
  EXPECT_GE(data.max, data.p99);
  // Speed 1 replays the source's own frames (ping-pong), so the rollout's strain is the data's.
  GroundTruth truth;
  const StressResult r = stress_rollout(truth, src, {60, 1.0, 0}, "truth", kStrainAllowance * data.p99);
  EXPECT_TRUE(r.passed()) << "strain p99 " << r.max_strain_p99 << " limit " << r.strain_limit;
  EXPECT_TRUE(r.within_strain());
  EXPECT_EQ(r.first_torn_frame, -1);
  EXPECT_LE(r.max_strain_p99, data.p99 + 1e-9);
  EXPECT_NEAR(r.max_strain_p99, data.p99, 1e-9);  // 57 frames cover every source frame
  EXPECT_NEAR(r.max_strain, data.max, 1e-9);
  // Per frame: p99 and max of edge_strains.
  const GarmentEdges edges = garment_edges(src);
  const std::vector<double> e = edge_strains(edges, garments_at(src, 5));
  const StrainExtremes f = frame_strain(edges, garments_at(src, 5));
  EXPECT_DOUBLE_EQ(f.p99, quantile(e, 0.99));
  EXPECT_DOUBLE_EQ(f.max, *std::max_element(e.begin(), e.end()));
}

// ---- the trained tiny model at the extremes -----------------------------------------------------

TEST_F(Extremes, RolloutsOf100FramesStayFiniteAtExtremeWindAndSpeed) {
  ModelPredictor p("tiny", model_->config, model_->params, stats_);
  std::vector<StressScene> scenes = {{100, 1.0, 0}, {100, 1.0, 400}, {100, 1.0, 2000}, {100, 5.0, -1}};
  for (const auto& s : scenes) {
    const StressResult r = stress_rollout(p, source_, s, "", kStrainAllowance * data_strain(source_, 0).p99);
    EXPECT_TRUE(r.finite) << "wind " << s.wind_strength << " speed " << s.speed << ": non-finite at frame "
                          << r.first_bad_frame;
    EXPECT_EQ(r.frames, 97);
    EXPECT_GT(r.max_vertex_speed, 0.0);
    // A one-epoch tiny model is not expected to keep the cloth on the body for 100 frames;
    // the bound is checked for the default model by `layersnet stress` (scripts/extremes.sh).
    std::printf("[ tiny    ] wind %6.0f speed %.0fx: max dist / bound %.3f, max speed %.3f units/frame, %.2f ms/frame\n",
                s.wind_strength, s.speed, r.max_bound_ratio, r.max_vertex_speed, r.ms_per_frame);
  }
}

// The model's rollouts with the patch tether (eval.patch_tether = 3; off by default): every predicted
// frame has every vertex within its limit of its patch mates, at 5x body speed too; the
// untethered rollout of the same model is printed for comparison.
TEST_F(Extremes, TetheredModelRolloutsKeepEveryVertexNearItsPatch) {
  const dataset::Sequence fast = make_stress_sequence(source_, {100, 5.0, -1.0});
  const auto structure = dataset::build_structure(fast.info, static_cast<float>(model_->config.model.patch_size));
  const std::vector<float> limit = tether_limits(fast, *structure, 3.0);
  Config tethered_config = model_->config;
  tethered_config.eval.patch_tether = 3.0;
  ModelPredictor tethered("tiny", tethered_config, model_->params, stats_);
  const Rollout held = rollout(tethered, fast, 2, 97);
  ASSERT_EQ(held.frames.size(), 97u);
  EXPECT_LT(held.diverged_at, 0);
  double worst = 0;
  for (const Points& x : held.frames) worst = std::max(worst, tether_ratio(structure->all, limit, x));
  EXPECT_LE(worst, 1.0 + 1e-3);
  Config free_config = model_->config;
  free_config.eval.patch_tether = 0.0;
  ModelPredictor free_model("tiny", free_config, model_->params, stats_);
  const Rollout loose = rollout(free_model, fast, 2, 97);
  double loose_worst = 0;
  for (const Points& x : loose.frames) loose_worst = std::max(loose_worst, tether_ratio(structure->all, limit, x));
  std::printf("[ tiny    ] 5x speed, 97 frames: worst offset / tether limit %.3f tethered, %.3f untethered\n", worst,
              loose_worst);
}

TEST_F(Extremes, Float64AgreesWithFloat32WithinTheModelsOwnError) {
  const PrecisionResult p = compare_precision(model_->config, model_->params, stats_, source_, 60);
  ASSERT_EQ(p.frames, 60);
  EXPECT_TRUE(p.finite);
  EXPECT_TRUE(p.passed()) << "worst mean divergence " << p.worst_mean() << " vs model error " << p.model_error;
  // One step from identical inputs: only rounding differs (float32 eps ~ 1e-7 relative on
  // positions of a few units, amplified by the network, still far below 1e-3 units = 0.01 mm).
  EXPECT_LT(p.max_divergence.front(), 1e-3);
  EXPECT_GT(p.model_error, 0.0);
  std::printf("[ tiny    ] float32 vs float64: frame 1 max %.3g, frame 60 mean %.3g, worst mean %.3g units; "
              "model error %.3g units\n",
              p.max_divergence.front(), p.mean_divergence.back(), p.worst_mean(), p.model_error);
}

// ---- degenerate inputs ------------------------------------------------------------------------------

enum class Degenerate { kNone, kCoincident, kZeroArea, kIsolatedPatch, kFarFromBody, kZeroWindQuaternion, kAll };

// Removes every edge of patch p (as receiver and as sender) from a CSR list over P.
void isolate(std::vector<int32_t>& offsets, std::vector<int32_t>& items, int32_t p, bool items_are_patches) {
  std::vector<int32_t> o{0}, it;
  for (size_t r = 0; r + 1 < offsets.size(); ++r) {
    for (int32_t k = offsets[r]; k < offsets[r + 1]; ++k)
      if (static_cast<int32_t>(r) != p && !(items_are_patches && items[static_cast<size_t>(k)] == p))
        it.push_back(items[static_cast<size_t>(k)]);
    o.push_back(static_cast<int32_t>(it.size()));
  }
  offsets = std::move(o);
  items = std::move(it);
}

// The data set's kind of sequence (synthetic_options) with one degenerate part, or all of
// them, at every frame.
dataset::Sequence degenerate_sequence(Degenerate kind) {
  dataset::Sequence s = dataset::make_synthetic_sequence(synthetic_options());
  const bool all = kind == Degenerate::kAll;
  const int T = s.info.num_frames, n = s.info.garments[0].num_vertices;
  dataset::Points& g0 = s.frames.garments[0];  // frame t at rows t*n ...
  if (kind == Degenerate::kCoincident || all)  // vertex 1 on top of vertex 0
    for (int t = 0; t < T; ++t) g0.row(t * n + 1) = g0.row(t * n);
  if (kind == Degenerate::kZeroArea || all) {  // the second face's corners on one line
    const auto f = s.info.garments[0].faces.row(1);
    for (int t = 0; t < T; ++t) g0.row(t * n + f(2)) = 0.5f * (g0.row(t * n + f(0)) + g0.row(t * n + f(1)));
  }
  if (kind == Degenerate::kFarFromBody || all)  // every garment 50 units away: no body neighbour
    for (auto& g : s.frames.garments) g.col(0).array() += 50.f;
  if (kind == Degenerate::kZeroWindQuaternion || all) {
    s.info.has_wind = true;
    s.info.wind_rotation.setZero(T, 4);
    s.info.wind_strength.setConstant(T, 400.f);
  }
  return s;
}

struct DegenerateWindow {
  model::ModelInput<float> input;
  losses::LossInput<float> target;
};

// The sample at t = 6 (wind blowing) through the production road; an isolated patch is cut out
// of the model input afterwards (no sequence makes one).
DegenerateWindow degenerate_window(const dataset::Sequence& seq, const ModelConfig& c,
                                   const dataset::NormalisationStats& stats, Degenerate kind) {
  const dataset::TrainingSample sample =
      dataset::build_sample(seq.info, seq.frames, 6, stats, nullptr, model::sample_options_for(c));
  DegenerateWindow w{model::model_input_from_sample(sample, stats, c), losses::loss_input_from_sample(sample, seq.info)};
  if (kind == Degenerate::kIsolatedPatch || kind == Degenerate::kAll) {  // patch 0: no neighbour of any kind
    isolate(w.input.mesh_offsets, w.input.mesh_senders, 0, true);
    isolate(w.input.world_offsets, w.input.world_senders, 0, true);
    isolate(w.input.body_offsets, w.input.body_tokens, 0, false);
    w.input.patch_body[0] = -1;
  }
  return w;
}

template <class T>
void expect_finite_forward_and_gradients(const ModelConfig& c, const model::ModelInput<float>& in32,
                                         const losses::LossInput<float>& target32, const ad::ParamStore<float>& p32,
                                         const std::string& what) {
  ad::ParamStore<T> ps;
  model::register_params(ps, c);
  std::copy(p32.values().begin(), p32.values().end(), ps.values().begin());
  const model::ModelInput<T> in = model::cast_input<T>(in32);
  const losses::LossInput<T> target = losses::cast_loss_input<T>(target32);
  ad::Tape<T> tape;
  ps.zero_grads();
  const model::Predictions<T> pred = model::forward(tape, ps, c, in);
  const auto v = pred.vertex.val();
  EXPECT_TRUE(v.allFinite()) << what;
  EXPECT_TRUE(pred.patch.val().allFinite()) << what;
  const losses::LossTerms<T> loss = losses::compute_losses(tape, ps, c, LossConfig{}, target, pred);
  ASSERT_TRUE(std::isfinite(static_cast<double>(loss.total.val()(0, 0)))) << what;
  tape.backward(loss.total);
  int bad = 0;
  double norm = 0;
  for (T g : ps.grads()) {
    bad += !std::isfinite(static_cast<double>(g));
    norm += static_cast<double>(g) * static_cast<double>(g);
  }
  EXPECT_EQ(bad, 0) << what << ": non-finite gradient entries";
  EXPECT_GT(norm, 0.0) << what << ": the loss reaches no parameter";
}

TEST_F(Extremes, DegenerateInputsGiveFiniteOutputsAndGradients) {
  const ModelConfig& c = model_->config.model;
  const std::pair<Degenerate, const char*> cases[] = {
      {Degenerate::kNone, "plain"},          {Degenerate::kCoincident, "coincident vertices"},
      {Degenerate::kZeroArea, "zero-area face"}, {Degenerate::kIsolatedPatch, "patch without neighbours"},
      {Degenerate::kFarFromBody, "garment far from the body"},
      {Degenerate::kZeroWindQuaternion, "all-zero wind quaternion"}, {Degenerate::kAll, "all at once"}};
  for (const auto& [kind, what] : cases) {
    const DegenerateWindow w = degenerate_window(degenerate_sequence(kind), c, stats_, kind);
    const model::ModelInput<float>& in = w.input;
    model::validate(in);
    if (kind == Degenerate::kFarFromBody) {
      EXPECT_EQ(in.body_offsets.back(), 0) << "the far garment still has body neighbours";
      for (int32_t b : in.vertex_body) EXPECT_EQ(b, -1);
    }
    if (kind == Degenerate::kIsolatedPatch) {
      EXPECT_EQ(in.mesh_offsets[1], 0);
      EXPECT_EQ(in.world_offsets[1], 0);
      EXPECT_EQ(in.body_offsets[1], 0);
    }
    expect_finite_forward_and_gradients<float>(c, in, w.target, model_->params, std::string(what) + " (float32)");
    expect_finite_forward_and_gradients<double>(c, in, w.target, model_->params, std::string(what) + " (float64)");
  }
}

// ---- 10x learning rate ------------------------------------------------------------------------------

// Trains with the given learning rate; either it finishes with finite parameters or the
// non-finite guard stops it with a message naming the fix. Every checkpoint left loads.
void expect_converges_or_stops_cleanly(const fs::path& root, const std::string& run, double lr) {
  std::ostringstream log;
  TrainOptions o;
  o.run_dir = (root / run).string();
  o.log = &log;
  const Config c = tiny_config((root / "data").string(),
                               {"train.learning_rate=" + std::to_string(lr), "train.checkpoint_every=2",
                                "train.max_nonfinite_in_row=3"});
  bool stopped = false;
  try {
    const TrainSummary s = train(c, o);
    EXPECT_TRUE(std::isfinite(s.last_loss)) << "lr " << lr;
    EXPECT_GT(s.updates, 0);
  } catch (const TrainingStopped& e) {
    stopped = true;
    const std::string msg = e.what();
    // Both stops name the run and the fix: the guard's (non-finite loss or gradient k times in a
    // row) and a refused checkpoint (the last update overflowed Adam's moments: finite gradients
    // ~1e20 at absurd rates, squared to inf in float).
    EXPECT_NE(msg.find(o.run_dir), std::string::npos) << msg;
    EXPECT_NE(msg.find("learning_rate"), std::string::npos) << msg;
    std::printf("[ lr %-5g] TrainingStopped: %s\n", lr, msg.c_str());
  }
  const auto all = list_checkpoints(o.run_dir);
  if (!stopped) {
    EXPECT_FALSE(all.empty());
  }
  std::vector<std::string> files = all;
  if (fs::exists(fs::path(o.run_dir) / "best.h5")) files.push_back((fs::path(o.run_dir) / "best.h5").string());
  for (const auto& f : files) {
    ad::ParamStore<float> p;
    model::register_params(p, c.model);
    ASSERT_NO_THROW(read_checkpoint(f, p)) << f;
    bool finite = true;
    for (float v : p.values()) finite = finite && std::isfinite(v);
    EXPECT_TRUE(finite) << f << " holds non-finite weights";
  }
  for (const auto& e : fs::directory_iterator(fs::path(o.run_dir) / "checkpoints"))
    EXPECT_NE(e.path().extension(), ".tmp") << "a torn checkpoint was left: " << e.path();
  std::printf("[ lr %-5g] %s, %zu checkpoint file(s) load with finite weights\n", lr,
              stopped ? "stopped (TrainingStopped)" : "finished with a finite loss", files.size());
}

TEST_F(Extremes, TenTimesTheLearningRateConvergesOrStopsCleanly) {
  expect_converges_or_stops_cleanly(root_, "lr10x", 1e-2);     // tiny/default 1e-3 x 10
  expect_converges_or_stops_cleanly(root_, "lr1e4x", 10.0);    // far beyond: whichever way, no crash
}

// ---- the command ---------------------------------------------------------------------------------------

std::string run(const std::string& args, int* code) { return cli_test::run_cli(args, code); }

TEST_F(Extremes, StressCommandPrintsTheTableAndWritesJson) {
  int code = 0;
  const fs::path json_path = root_ / "stress.json";
  const std::string text = run("stress --checkpoint " + checkpoint_ + " --dataset " + (root_ / "data").string() +
                                   " --frames 30 --winds 0,2000 --speed 5 --precision-frames 20 --threads 2 --json " +
                                   json_path.string(),
                               &code);
  ASSERT_TRUE(code == 0 || code == 4) << text;  // 4: a run broke its bound (a verdict, not an error)
  EXPECT_NE(text.find("| wind 2000 |"), std::string::npos) << text;
  EXPECT_NE(text.find("| top speed 5x (s="), std::string::npos) << text;
  EXPECT_NE(text.find("float32 vs float64 over 20 frames"), std::string::npos) << text;
  std::ifstream in(json_path);
  const auto j = nlohmann::json::parse(in);
  EXPECT_EQ(code, j["passed"].get<bool>() ? 0 : 4) << text;
  ASSERT_EQ(j["runs"].size(), 3u);
  for (const auto& r : j["runs"]) {
    EXPECT_EQ(r["frames"], 27);
    EXPECT_TRUE(r["finite"].get<bool>()) << r["label"];
  }
  EXPECT_EQ(j["precision"]["frames"], 20);
  // The strain limit: kStrainAllowance x the worst p99 over every sequence of the data set.
  const dataset::DatasetManifest manifest = dataset::read_manifest((root_ / "data").string());
  const StrainExtremes data = data_set_strain(manifest);
  double worst = 0;
  for (const std::string& id : manifest.all_ids())
    worst = std::max(worst, data_strain(dataset::read_sequence(manifest.sequence_path(id)), 0).p99);
  EXPECT_DOUBLE_EQ(data.p99, worst);
  // The report keeps 7 significant digits (float32's).
  EXPECT_NEAR(j["data_strain_p99"].get<double>(), data.p99, 1e-6 * data.p99);
  EXPECT_NEAR(j["strain_limit"].get<double>(), kStrainAllowance * data.p99, 1e-6 * kStrainAllowance * data.p99);
  EXPECT_NE(text.find("max strain p99 (limit"), std::string::npos) << text;
  for (const auto& r : j["runs"]) {
    EXPECT_EQ(r["per_frame"]["strain_p99"].size(), 27u);
    EXPECT_EQ(r["strain_limit"].get<double>(), j["strain_limit"].get<double>());
    EXPECT_EQ(r["passed"].get<bool>(),
              r["within_bound"].get<bool>() && r["within_strain"].get<bool>() && r["finite"].get<bool>());
  }
  EXPECT_EQ(code == 0, j["passed"].get<bool>()) << text;
  const std::string bad = run("stress --checkpoint " + (root_ / "missing.h5").string(), &code);
  EXPECT_NE(code, 0);
  EXPECT_NE(bad.find("missing.h5"), std::string::npos) << bad;
}

}  // namespace
}  // namespace layersnet::eval
