// The patch tether (eval/tether.h): real cloth is never moved, a runaway vertex is pulled
// back onto its sphere without dragging its patch mates, and rollouts of a predictor that
// throws vertices away stay within the limits.
#include "dataset/synthetic.h"
#include "eval/rollout.h"
#include "eval/tether.h"
#include "run/config.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <string>

namespace layersnet::eval {
namespace {

dataset::SyntheticOptions options() {
  dataset::SyntheticOptions o;
  o.garments = 2;
  o.frames = 10;
  o.rings = 5;
  o.segments = 16;
  return o;
}

// Largest |x_v − c| / L_v, c the mean of the other members of v's own patch (the tether's
// centre), computed here member by member.
double worst_over_limit(const dataset::PatchStructure& s, const std::vector<float>& limit, const Points& x) {
  double worst = 0;
  for (int v = 0; v < s.num_vertices; ++v) {
    const int p = s.own_patch[v];
    if (p < 0 || s.patch_vertices.size(p) < 2) continue;
    Eigen::RowVector3f centre = Eigen::RowVector3f::Zero();
    for (const int32_t* u = s.patch_vertices.begin(p); u != s.patch_vertices.end(p); ++u)
      if (*u != v) centre += x.row(*u);
    centre /= static_cast<float>(s.patch_vertices.size(p) - 1);
    worst = std::max(worst, (x.row(v) - centre).norm() / double(limit[v]));
  }
  return worst;
}

// A vertex whose own patch has at least `members` members.
int vertex_in_patch_of(const dataset::PatchStructure& s, int members) {
  for (int v = 0; v < s.num_vertices; ++v)
    if (s.own_patch[v] >= 0 && s.patch_vertices.size(s.own_patch[v]) >= members) return v;
  return -1;
}

TEST(PatchTether, LimitsAreFactorTimesTheRestPatchRadius) {
  const dataset::Sequence seq = dataset::make_synthetic_sequence(options());
  const auto structure = dataset::build_structure(seq.info, dataset::kDefaultPatchSize);
  const std::vector<float> one = tether_limits(seq, *structure, 1.0), three = tether_limits(seq, *structure, 3.0);
  ASSERT_EQ(one.size(), static_cast<size_t>(seq.info.total_garment_vertices()));
  for (size_t v = 0; v < one.size(); ++v) {
    EXPECT_GT(one[v], 0.f) << v;
    EXPECT_NEAR(three[v], 3.f * one[v], 1e-5f * three[v]);
  }
  // At rest every member lies within its patch's radius of the centre (factor 1).
  EXPECT_LE(worst_over_limit(structure->all, one, rest_garments(seq)), 1.0 + 1e-5);
  // The data: ratio of the generator's cloth to its own rest radii, above 0, real cloth unmoved.
  const double ratio = data_tether_ratio(seq, *structure, 0);
  EXPECT_GT(ratio, 0.0);
  for (int t = 0; t < seq.info.num_frames; ++t) {
    Points x = garments_at(seq, t);
    const Points before = x;
    EXPECT_EQ(apply_tether(structure->all, tether_limits(seq, *structure, 1.01 * ratio), x), 0) << "frame " << t;
    EXPECT_EQ(x, before);
  }
}

TEST(PatchTether, PullsARunawayBackWithoutDraggingItsPatchMates) {
  const dataset::Sequence seq = dataset::make_synthetic_sequence(options());
  const auto structure = dataset::build_structure(seq.info, dataset::kDefaultPatchSize);
  const dataset::PatchStructure& s = structure->all;
  const std::vector<float> limit = tether_limits(seq, *structure, 3.0);
  const int v = vertex_in_patch_of(s, 3);
  ASSERT_GE(v, 0);
  const int p = s.own_patch[v];
  Points x = garments_at(seq, 4);
  const Points truth = x;
  const Eigen::RowVector3f direction = Eigen::RowVector3f(0.6f, -0.8f, 0.f);
  x.row(v) += 100.f * direction;  // far beyond any patch
  // The centre the projection must use: the patch mates' mean without the runaway.
  Eigen::RowVector3f mates = Eigen::RowVector3f::Zero();
  int count = 0;
  for (const int32_t* u = s.patch_vertices.begin(p); u != s.patch_vertices.end(p); ++u)
    if (*u != v) mates += x.row(*u), ++count;
  mates /= static_cast<float>(count);
  EXPECT_EQ(apply_tether(s, limit, x), 1);
  EXPECT_NEAR((x.row(v) - mates).norm(), limit[v], 1e-4f * limit[v]);
  // Only the runaway moved, along the line from the centre through where it was.
  for (int u = 0; u < s.num_vertices; ++u) {
    if (u == v) continue;
    ASSERT_EQ(x.row(u), truth.row(u)) << u;
  }
  const Eigen::RowVector3f thrown = truth.row(v) + 100.f * direction;
  EXPECT_NEAR((x.row(v) - mates).normalized().dot((thrown - mates).normalized()), 1.f, 1e-5f);
  // A second pass finds nothing to do.
  EXPECT_EQ(apply_tether(s, limit, x), 0);
}

TEST(PatchTether, LeavesNonFiniteRowsVisible) {
  const dataset::Sequence seq = dataset::make_synthetic_sequence(options());
  const auto structure = dataset::build_structure(seq.info, dataset::kDefaultPatchSize);
  Points x = garments_at(seq, 2);
  x.row(0).setConstant(std::numeric_limits<float>::quiet_NaN());
  apply_tether(structure->all, tether_limits(seq, *structure, 3.0), x);
  EXPECT_TRUE(std::isnan(x(0, 0)));
}

// Throws one vertex 50 units further every step: without the tether it leaves, with it every
// step ends within the limits (the predictor's offsets, not the model's, so the test does not
// depend on a trained model).
struct ThrowOneVertex : Predictor {
  explicit ThrowOneVertex(int v) : vertex(v) {}
  std::string name() const override { return "throw"; }
  Points step(const dataset::Sequence&, int, const Points&, const Points&, const Points& now) override {
    Points x = now;
    x(vertex, 2) += 50.f;
    return x;
  }
  int vertex;
};

struct Tethered : Predictor {
  Tethered(Predictor& inner, const dataset::PatchStructure& s, std::vector<float> limit)
      : inner(inner), patches(s), limit(std::move(limit)) {}
  std::string name() const override { return "tethered"; }
  Points step(const dataset::Sequence& seq, int t, const Points& a, const Points& b, const Points& c) override {
    Points x = inner.step(seq, t, a, b, c);
    apply_tether(patches, limit, x);
    return x;
  }
  Predictor& inner;
  const dataset::PatchStructure& patches;
  std::vector<float> limit;
};

TEST(PatchTether, KeepsEveryStepOfARolloutWithinTheLimits) {
  const dataset::Sequence seq = dataset::make_synthetic_sequence(options());
  const auto structure = dataset::build_structure(seq.info, dataset::kDefaultPatchSize);
  const std::vector<float> limit = tether_limits(seq, *structure, 3.0);
  const int v = vertex_in_patch_of(structure->all, 3);
  ThrowOneVertex loose(v);
  const Rollout free_run = rollout(loose, seq, 2, 6);
  EXPECT_GT(worst_over_limit(structure->all, limit, free_run.frames.back()), 10.0);
  EXPECT_NEAR(tether_ratio(structure->all, limit, free_run.frames.back()),
              worst_over_limit(structure->all, limit, free_run.frames.back()), 1e-6);
  Tethered tethered(loose, structure->all, limit);
  const Rollout held = rollout(tethered, seq, 2, 6);
  for (const Points& x : held.frames) {
    EXPECT_LE(worst_over_limit(structure->all, limit, x), 1.0 + 1e-4);
    EXPECT_NEAR(tether_ratio(structure->all, limit, x), worst_over_limit(structure->all, limit, x), 1e-6);
  }
}

// Off unless asked for: the code default, and the shipped default / quick configs set
// nothing; `eval.patch_tether` still turns it on.
TEST(PatchTether, IsOffByDefaultAndStaysAnOption) {
  EXPECT_EQ(Config{}.eval.patch_tether, 0.0);
  const std::string configs = std::string(LAYERSNET_SOURCE_DIR) + "/configs/";
  for (const char* file : {"default.toml", "quick.toml"})
    EXPECT_EQ(load_config({configs + file}).eval.patch_tether, 0.0) << file;
  EXPECT_EQ(load_config({configs + "default.toml"}, {"eval.patch_tether=3"}).eval.patch_tether, 3.0);
}

}  // namespace
}  // namespace layersnet::eval
