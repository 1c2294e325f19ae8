#pragma once
// Timing helpers shared by the model benchmarks (bench model, scaling, scene).
#include "autodiff/params.h"
#include "autodiff/tape.h"
#include "model/input_builder.h"
#include "model/layersnet.h"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <fstream>
#include <string>
#include <vector>

namespace layersnet::bench {

inline double now_ms() {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

inline double median(std::vector<double> v) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  const std::size_t n = v.size();
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

// The three load averages of /proc/loadavg, "a b c".
inline std::string uptime_load() {
  std::ifstream f("/proc/loadavg");
  double a = 0, b = 0, c = 0;
  f >> a >> b >> c;
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.2f %.2f %.2f", a, b, c);
  return buf;
}

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

// One inference step as a rollout pays it: model input built from the scene (incl. the
// neighbour searches), then the forward without recording, with its stage times.
struct InferenceTiming {
  double input_ms = 0, forward_ms = 0;  // wall
  model::StageTimes stages;
};
inline InferenceTiming time_inference(const model::SceneWindow& scene, const ModelConfig& mc,
                                      ad::ParamStore<float>& ps, ad::Tape<float>& tape) {
  InferenceTiming r;
  double t0 = now_ms();
  const auto in = model::cast_input<float>(model::build_model_input(scene, mc));
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
