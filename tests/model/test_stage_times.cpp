// ForwardOptions::times (the stage-timing hook of the cost benches) and the scene variants of
// model/scene_variants.h: timing is filled and consistent and changes no value; each removed
// scene part really is absent from the model input and from the forward's work counts.
#include "autodiff/ops_dense.h"
#include "model/layersnet.h"
#include "model/params_layout.h"
#include "model/scene_variants.h"
#include "model_test_util.h"

#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <cstring>

namespace layersnet::model {
namespace {

struct Fixture {
  ModelConfig config = testing::tiny_config();
  ad::ParamStore<float> params;
  Fixture() {
    register_params(params, config);
    init_params(params, config, 3);
  }
};

ModelInput<float> input_of(const SceneWindow& s, const ModelConfig& c) { return cast_input<float>(build_model_input(s, c)); }

std::vector<float> values(const ad::Var<float>& v) { return {v.value, v.value + v.size()}; }

bool same_bits(const std::vector<float>& a, const std::vector<float>& b) {
  return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(float)) == 0;
}

TEST(StageTimes, FilledNonNegativeAndWithinTheTotal) {
  Fixture f;
  const auto in = input_of(make_synthetic_scene(testing::tiny_scene()), f.config);
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
    const auto in = input_of(make_synthetic_scene(testing::tiny_scene(wind)), f.config);
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
  const auto in = input_of(make_synthetic_scene(testing::tiny_scene()), f.config);
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

TEST(SceneVariants, BodyFarHasNoBodyRowsOrTokens) {
  Fixture f;
  const auto near = make_synthetic_scene(testing::tiny_scene());
  auto far = near;
  const double up[3] = {0, 0, 10 * f.config.body_radius + 10};
  move_body(far, up);
  const auto in_near = input_of(near, f.config), in = input_of(far, f.config);
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
  const auto with = make_synthetic_scene(testing::tiny_scene());
  auto calm = with;
  drop_wind(calm);
  const auto in_with = input_of(with, f.config), in = input_of(calm, f.config);
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
  const auto full = make_synthetic_scene(testing::tiny_scene());
  const auto one = keep_first_garments(full, 1);
  const auto solo = make_synthetic_scene(testing::tiny_scene(true, 1));
  // Same sizes as a scene made with that garment alone (its motion differs: the generator's
  // random stream continues into the second garment and the body).
  EXPECT_EQ(one.N, solo.N);
  EXPECT_EQ(one.P, solo.P);
  EXPECT_EQ(one.faces, solo.faces);
  EXPECT_EQ(one.adj_offsets, solo.adj_offsets);
  EXPECT_EQ(one.adj_patches, solo.adj_patches);
  EXPECT_EQ(one.v2p_patches, solo.v2p_patches);
  EXPECT_EQ(one.p2v_vertices, solo.p2v_vertices);

  const auto in_full = input_of(full, f.config), in = input_of(one, f.config);
  ASSERT_EQ(in.N, full.garment_offsets[1]);
  EXPECT_TRUE(std::equal(in.state.begin(), in.state.end(), in_full.state.begin()));  // same motion
  EXPECT_LT(in.world_senders.size(), in_full.world_senders.size());  // the inter-garment world edges are gone
  for (int32_t p : in.world_senders) EXPECT_LT(p, in.P);
  EXPECT_THROW(keep_first_garments(full, 3), CheckError);
}

}  // namespace
}  // namespace layersnet::model
