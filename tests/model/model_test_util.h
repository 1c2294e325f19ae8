#pragma once
// Shared fixtures for the model tests: a tiny configuration, a small synthetic sequence, and
// its windows through the production road (dataset::build_sample -> losses::add_physics_step ->
// model_input_from_sample, losses::loss_input_from_sample); drawn values for parameters that start at zero.
#include "autodiff/params.h"
#include "dataset/sample.h"
#include "dataset/stats.h"
#include "dataset/synthetic.h"
#include "losses/physics_step.h"
#include "losses/sample_loss_input.h"
#include "model/model_config.h"
#include "model/sample_input.h"
#include "run/config.h"

#include <cstdint>
#include <random>
#include <string>

namespace layersnet::model::testing {

// Overwrites the tensor `name` with N(0, 0.3²) draws from `seed`, so that the paths behind a
// parameter that starts at zero change the output and carry a gradient.
inline void draw_normal(ad::ParamStore<double>& ps, const std::string& name, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> normal(0, 0.3);
  for (auto& x : ps.value(ps.index_of(name))) x = normal(rng);
}

// The tests' one tiny model: the [model] section of configs/tiny.toml, which the trainer and
// command-line tests train too; small enough for a double-precision whole-model gradient check
// in well under a second.
inline ModelConfig tiny_config() {
  return load_config({std::string(LAYERSNET_SOURCE_DIR) + "/configs/tiny.toml"}).model;
}

// Two sheets (9 x 6 and 10 x 6 vertices 0.1 apart, patches of 3 x 3 quads) 0.05 and 0.065 outside
// a body cylinder of radius 1 (12 x 8 vertices): the garments lag the body's sway and ripple, so
// some of their vertices touch the body and the layers touch each other. 6 frames.
inline dataset::SyntheticOptions tiny_scene(bool wind = true, int garments = 2) {
  dataset::SyntheticOptions o;
  o.frames = 6;
  o.sheets = {{9, 6, 1.05f, 0.f}, {10, 6, 1.065f, -0.05f}};
  o.sheets.resize(garments);
  o.body_segments = 12;
  o.body_rings = 8;
  o.body_radius = 1.f;
  o.body_bottom = -0.3f;
  o.height = 1.4f;
  o.body_caps = false;
  o.wind = wind;
  return o;
}
inline constexpr int kFrame = 3;  // sample frame t of tiny_scene: the wind (if any) blows at t and t+1

// One sample of a sequence, its model input and its loss target.
struct Window {
  dataset::TrainingSample sample;
  ModelInput<float> input;
  losses::LossInput<float> target;
};

inline Window window(const dataset::Sequence& seq, const dataset::NormalisationStats& stats, const ModelConfig& c,
                     int t = kFrame) {
  Window w;
  w.sample = dataset::build_sample(seq.info, seq.frames, t, stats, nullptr, sample_options_for(c));
  losses::add_physics_step(w.sample, seq.info, c);  // as the trainer and the rollouts do
  w.input = model_input_from_sample(w.sample, stats, c);
  w.target = losses::loss_input_from_sample(w.sample, seq.info);
  return w;
}

// The same with the sequence's own statistics.
inline Window window(const dataset::Sequence& seq, const ModelConfig& c, int t = kFrame) {
  return window(seq, dataset::compute_stats(seq), c, t);
}

}  // namespace layersnet::model::testing
