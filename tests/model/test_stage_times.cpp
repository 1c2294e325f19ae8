// ForwardOptions::times (the stage-timing hook of the cost benches) and the scene variants that
// `bench scene` times (synthetic options: fewer garments, no wind, body moved away): timing is
// filled and consistent and changes no value; each variant is the full sequence minus that
// part, and the part really is absent from the model input and from the forward's work counts.
#include "autodiff/ops_dense.h"
#include "model/layersnet.h"
#include "model/params_layout.h"
#include "model_test_util.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>

namespace layersnet::model {
namespace {

struct Fixture {
  ModelConfig config = testing::tiny_config();
  ad::ParamStore<float> params;
  dataset::NormalisationStats stats = dataset::compute_stats(dataset::make_synthetic_sequence(testing::tiny_scene()));
  Fixture() {
    register_params(params, config);
    init_params(params, config, 3);
  }
  // Every variant with the full scene's statistics.
  ModelInput<float> input_of(const dataset::SyntheticOptions& o) const {
    return testing::window(dataset::make_synthetic_sequence(o), stats, config).input;
  }
};

std::vector<float> values(const ad::Var<float>& v) { return {v.value, v.value + v.size()}; }

bool same_bits(const std::vector<float>& a, const std::vector<float>& b) {
  return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(float)) == 0;
}

TEST(StageTimes, FilledNonNegativeAndWithinTheTotal) {
  Fixture f;
  const auto in = f.input_of(testing::tiny_scene());
  ASSERT_GT(in.U, 0);
  ad::Tape<float> tape;
  StageTimes t;
  t.decoder_ms = 1e9;  // forward overwrites, never accumulates into old values
  ForwardOptions opt;
  opt.times = &t;
  for (bool record : {false, true}) {
    tape.reset();
    tape.set_recording(record);
    const auto t0 = std::chrono::steady_clock::now();
    forward(tape, f.params, f.config, in, opt);
    const double outside = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    const double stages = t.graph_ms + t.encoder_ms + t.attention_ms + t.ffn_ms + t.decoder_ms;
    for (double x : {t.graph_ms, t.encoder_ms, t.attention_ms, t.attention_edges_ms, t.attention_inter_ms, t.ffn_ms,
                     t.decoder_ms, t.encoder_body_ms})
      EXPECT_GT(x, 0.0) << "record " << record;  // every stage ran (U > 0 here)
    EXPECT_LE(stages, t.total_ms);
    EXPECT_LE(t.total_ms, outside);
    EXPECT_LE(t.encoder_body_ms, t.encoder_ms);
    EXPECT_LE(t.attention_inter_ms, t.attention_edges_ms);
    EXPECT_LE(t.attention_edges_ms, t.attention_ms);
  }
  tape.set_recording(true);
}

TEST(StageTimes, WorkCountsMatchTheInput) {
  Fixture f;
  for (bool wind : {true, false}) {
    const auto in = f.input_of(testing::tiny_scene(wind));
    ad::Tape<float> tape;
    ad::NoRecord<float> off(tape);
    StageTimes t;
    ForwardOptions opt;
    opt.times = &t;
    forward(tape, f.params, f.config, in, opt);
    const int64_t ext = wind ? 2 : 1;  // [wind] + gravity
    EXPECT_EQ(t.patch_rows, in.P);
    EXPECT_EQ(t.vertex_rows, in.N);
    EXPECT_EQ(t.body_tokens, in.U);
    EXPECT_EQ(t.ext_tokens, ext);
    EXPECT_EQ(t.token_rows, in.P + in.A + in.U + ext);
    EXPECT_EQ(t.world_rows, static_cast<int64_t>(in.world_senders.size()));
    EXPECT_EQ(t.body_rows, static_cast<int64_t>(in.body_tokens.size()));
    EXPECT_EQ(t.inter_rows, t.body_rows + ext * in.P);  // every patch sees gravity (and wind)
    EXPECT_EQ(t.mesh_rows, static_cast<int64_t>(in.mesh_senders.size()) + in.P);  // + attribute token
    EXPECT_EQ(t.candidate_rows, static_cast<int64_t>(in.cand_patches.size()));
  }
}

// Timing reads the clock between ops only: predictions and gradients are bit-identical.
TEST(StageTimes, TimingChangesNoValue) {
  Fixture f;
  const auto in = f.input_of(testing::tiny_scene());
  auto run = [&](bool timed, std::vector<float>& grads) {
    ad::Tape<float> tape;
    StageTimes t;
    ForwardOptions opt;
    opt.times = timed ? &t : nullptr;
    f.params.zero_grads();
    const auto pred = forward(tape, f.params, f.config, in, opt);
    std::vector<float> out = values(pred.vertex), patch = values(pred.patch);
    out.insert(out.end(), patch.begin(), patch.end());
    tape.backward(ad::sum_all(tape, pred.vertex));
    grads.clear();
    for (const auto& e : f.params.entries()) {
      const auto g = f.params.var(e.name);
      grads.insert(grads.end(), g.grad, g.grad + g.size());
    }
    return out;
  };
  std::vector<float> g_off, g_on;
  const auto off = run(false, g_off), on = run(true, g_on);
  EXPECT_TRUE(same_bits(off, on));
  EXPECT_TRUE(same_bits(g_off, g_on));
  for (float x : on) ASSERT_TRUE(std::isfinite(x));
}

// The full sequence and a variant share every part the variant keeps, bit for bit.
void expect_same_motion(const dataset::Sequence& a, const dataset::Sequence& b, int garments) {
  for (int g = 0; g < garments; ++g) {
    EXPECT_TRUE(a.info.garments[g].faces == b.info.garments[g].faces) << "garment " << g;
    EXPECT_TRUE(a.info.garments[g].uv == b.info.garments[g].uv) << "garment " << g;
    EXPECT_TRUE(a.frames.garments[g] == b.frames.garments[g]) << "garment " << g;
  }
  EXPECT_TRUE(a.info.translation == b.info.translation);
}

TEST(SceneVariants, BodyFarHasNoBodyRowsOrTokens) {
  Fixture f;
  auto far_scene = testing::tiny_scene();
  far_scene.body_offset = {0.f, 0.f, static_cast<float>(10 * f.config.body_radius + 10)};
  expect_same_motion(dataset::make_synthetic_sequence(far_scene), dataset::make_synthetic_sequence(testing::tiny_scene()), 2);
  const auto in_near = f.input_of(testing::tiny_scene()), in = f.input_of(far_scene);
  ASSERT_GT(in_near.U, 0);  // otherwise the check below is vacuous
  ASSERT_GT(in_near.body_tokens.size(), 0u);
  EXPECT_EQ(in.U, 0);
  EXPECT_TRUE(in.body_tokens.empty());
  for (int32_t o : in.body_offsets) EXPECT_EQ(o, 0);
  for (int32_t b : in.patch_body) EXPECT_EQ(b, -1);
  for (int32_t b : in.vertex_body) EXPECT_EQ(b, -1);
  EXPECT_TRUE(same_bits(in.state, in_near.state));  // same garment motion

  ad::Tape<float> tape;
  ad::NoRecord<float> off(tape);
  StageTimes t;
  ForwardOptions opt;
  opt.times = &t;
  const auto pred = forward(tape, f.params, f.config, in, opt);
  EXPECT_EQ(t.body_tokens, 0);
  EXPECT_EQ(t.body_rows, 0);
  EXPECT_EQ(t.encoder_body_ms, 0.0);  // the body encoder did not run
  EXPECT_EQ(t.inter_rows, 2 * in.P);  // wind + gravity only
  for (int64_t i = 0; i < pred.vertex.size(); ++i) ASSERT_TRUE(std::isfinite(pred.vertex.value[i]));
}

TEST(SceneVariants, NoWindHasNoWindToken) {
  Fixture f;
  const auto with = dataset::make_synthetic_sequence(testing::tiny_scene(true));
  const auto calm = dataset::make_synthetic_sequence(testing::tiny_scene(false));
  expect_same_motion(calm, with, 2);
  EXPECT_TRUE(calm.frames.body == with.frames.body);
  const auto in_with = f.input_of(testing::tiny_scene(true)), in = f.input_of(testing::tiny_scene(false));
  EXPECT_TRUE(in_with.has_wind);
  EXPECT_FALSE(in.has_wind);
  EXPECT_TRUE(in.wind.empty());
  EXPECT_TRUE(in.wind_rot.empty());
  EXPECT_TRUE(same_bits(in.state, in_with.state));
  EXPECT_EQ(in.U, in_with.U);

  ad::Tape<float> tape;
  ad::NoRecord<float> off(tape);
  StageTimes t_with, t;
  ForwardOptions opt;
  opt.times = &t_with;
  forward(tape, f.params, f.config, in_with, opt);
  opt.times = &t;
  forward(tape, f.params, f.config, in, opt);
  EXPECT_EQ(t.ext_tokens, 1);  // gravity only
  EXPECT_EQ(t_with.ext_tokens, 2);
  EXPECT_EQ(t_with.token_rows - t.token_rows, 1);
  EXPECT_EQ(t_with.inter_rows - t.inter_rows, in.P);  // one wind edge per patch
}

TEST(SceneVariants, OneGarmentIsTheFirstGarmentOfTheFullScene) {
  Fixture f;
  const auto full = dataset::make_synthetic_sequence(testing::tiny_scene());
  const auto one = dataset::make_synthetic_sequence(testing::tiny_scene(true, 1));
  ASSERT_EQ(one.info.num_garments(), 1);
  expect_same_motion(one, full, 1);
  EXPECT_TRUE(one.frames.body == full.frames.body);

  const auto in_full = f.input_of(testing::tiny_scene()), in = f.input_of(testing::tiny_scene(true, 1));
  ASSERT_EQ(in.N, full.info.garments[0].num_vertices);
  ASSERT_LT(in.P, in_full.P);
  EXPECT_TRUE(std::equal(in.state.begin(), in.state.end(), in_full.state.begin()));  // same motion
  // Its patches are the full scene's first ones (garment order).
  EXPECT_TRUE(std::equal(in.v2p_offsets.begin(), in.v2p_offsets.end(), in_full.v2p_offsets.begin()));
  EXPECT_TRUE(std::equal(in.v2p_patches.begin(), in.v2p_patches.end(), in_full.v2p_patches.begin()));
  EXPECT_TRUE(std::equal(in.p2v_offsets.begin(), in.p2v_offsets.end(), in_full.p2v_offsets.begin()));
  EXPECT_TRUE(std::equal(in.p2v_vertices.begin(), in.p2v_vertices.end(), in_full.p2v_vertices.begin()));
  EXPECT_TRUE(std::equal(in.mesh_offsets.begin(), in.mesh_offsets.end(), in_full.mesh_offsets.begin()));
  EXPECT_TRUE(std::equal(in.mesh_senders.begin(), in.mesh_senders.end(), in_full.mesh_senders.begin()));
  EXPECT_LT(in.world_senders.size(), in_full.world_senders.size());  // the inter-garment world edges are gone
  for (int32_t p : in.world_senders) EXPECT_LT(p, in.P);
}

}  // namespace
}  // namespace layersnet::model
