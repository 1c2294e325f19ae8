#pragma once
// Timing helpers and synthetic scenes shared by the model benchmarks (bench model, scaling,
// scene). Scenes are dataset::Sequences; their inputs go the production road
// (dataset::build_sample -> model::model_input_from_sample, losses::loss_input_from_sample).
#include "autodiff/params.h"
#include "autodiff/tape.h"
#include "dataset/sample.h"
#include "dataset/stats.h"
#include "dataset/synthetic.h"
#include "eval/machine.h"
#include "model/layersnet.h"
#include "model/sample_input.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <memory>
#include <string>
#include <vector>

namespace layersnet::bench {

inline double now_ms() {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

using eval::median;  // the reports' median of timings (eval/machine.h)

// Per-field medians of the stage times (ms); the work counts are the first sample's.
inline model::StageTimes median_times(const std::vector<model::StageTimes>& v) {
  model::StageTimes m = v.empty() ? model::StageTimes{} : v.front();
  for (auto f : {&model::StageTimes::graph_ms, &model::StageTimes::encoder_ms, &model::StageTimes::encoder_body_ms,
                 &model::StageTimes::attention_ms, &model::StageTimes::attention_edges_ms,
                 &model::StageTimes::attention_inter_ms, &model::StageTimes::ffn_ms, &model::StageTimes::decoder_ms,
                 &model::StageTimes::total_ms}) {
    std::vector<double> x;
    for (const auto& t : v) x.push_back(t.*f);
    m.*f = median(x);
  }
  return m;
}

// A synthetic scene as a rollout sees it: the sequence, statistics computed from it, and its
// patch structure (static, built once as a rollout caches it). Samples are taken at frame t.
struct Scene {
  dataset::Sequence seq;
  dataset::NormalisationStats stats;
  std::shared_ptr<const dataset::SequenceStructure> structure;
  int t = 0;
};

// t = the middle frame: with 6 frames, t = 3 and the synthetic wind blows at t and t+1.
inline Scene make_scene(const dataset::SyntheticOptions& options, const ModelConfig& mc) {
  Scene s;
  s.seq = dataset::make_synthetic_sequence(options);
  s.stats = dataset::compute_stats(s.seq);
  s.structure = dataset::build_structure(s.seq.info, static_cast<float>(mc.patch_size));
  s.t = s.seq.info.num_frames / 2;
  return s;
}

// The sample at scene.t as a rollout step builds it (neighbour searches included).
inline dataset::TrainingSample sample_of(const Scene& s, const ModelConfig& mc) {
  return dataset::build_sample(s.seq.info, s.seq.frames, s.t, s.stats, s.structure, model::sample_options_for(mc));
}

// The outfit of `bench scaling` and `bench scene`: two open cylindrical sheets of fixed metric
// extent (inner 5.0 x 4.0, outer 6.25 x 4.75 scene units, radii 1.235 / 1.26, first rows at 0
// and -0.2) around a body of 106 x 65 = 6890 vertices (radius 1.2, from 0.6 below to 0.6 above
// the garments) that never changes, meshed at about `target` garment vertices: spacing
// h = sqrt(area / target). Wind on, 6 frames. Patches: the caller sets each sheet's uv_step.
struct OutfitGarment {
  double around, along, radius, z0;  // extent (scene units), nominal radius, first row height
};
inline constexpr OutfitGarment kOutfit[2] = {{5.0, 4.0, 1.235, 0.0}, {6.25, 4.75, 1.26, -0.2}};
inline dataset::SyntheticOptions outfit(int64_t target) {
  double area = 0, zmax = 0;
  for (const auto& g : kOutfit) area += g.around * g.along, zmax = std::max(zmax, g.z0 + g.along);
  const double h = std::sqrt(area / static_cast<double>(target));
  dataset::SyntheticOptions o;
  o.frames = 6;
  for (const auto& g : kOutfit)
    o.sheets.push_back({static_cast<int>(std::lround(g.around / h)) + 1, static_cast<int>(std::lround(g.along / h)) + 1,
                        static_cast<float>(g.radius), static_cast<float>(g.z0)});
  o.sheet_spacing = static_cast<float>(h);
  o.body_segments = 106;
  o.body_rings = 65;
  o.body_radius = 1.2f;
  o.body_bottom = -0.6f;
  o.height = static_cast<float>(zmax + 1.2);
  o.body_caps = false;
  o.wind = true;
  o.seed = 0;
  return o;
}

// One inference step as a rollout pays it: the sample (incl. the neighbour searches) and the
// model input, then the forward without recording, with its stage times.
struct InferenceTiming {
  double input_ms = 0, forward_ms = 0;  // wall
  model::StageTimes stages;
};
inline InferenceTiming time_inference(const Scene& scene, const ModelConfig& mc, ad::ParamStore<float>& ps,
                                      ad::Tape<float>& tape) {
  InferenceTiming r;
  double t0 = now_ms();
  const auto in = model::model_input_from_sample(sample_of(scene, mc), scene.stats, mc);
  r.input_ms = now_ms() - t0;
  model::ForwardOptions fo;
  fo.times = &r.stages;
  t0 = now_ms();
  {
    tape.reset();
    ad::NoRecord<float> off(tape);
    model::forward(tape, ps, mc, in, fo);
  }
  r.forward_ms = now_ms() - t0;
  return r;
}

}  // namespace layersnet::bench
