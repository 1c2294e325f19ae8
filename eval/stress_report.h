#pragma once
// `layersnet stress` as a library call: loads a checkpoint's model (load_model_predictor), runs
// the stress scenes of eval/stress.h at constant winds and a sped-up body, and float32 against
// float64 over the same checkpoint; prints one table and writes the results as JSON.
#include "eval/stress.h"

#include <nlohmann/json.hpp>

#include <string>
#include <vector>

namespace layersnet::eval {

struct StressOptions {
  std::string checkpoint;
  std::string dataset;  // empty: the checkpoint's data.dataset
  std::string sequence;  // empty: the first test sequence
  int frames = 600;
  std::vector<double> winds = {0, 400, 2000};
  bool no_winds = false;  // --no-winds: only the speed run
  double speed = 5;
  bool speed_factor = false;  // --speed is the time factor s itself, not a multiple of the top speed
  int precision_frames = 100;
  int first_frame = -1;
  double tether = -1;  // < 0: the checkpoint config's eval.patch_tether
  std::vector<std::string> settings;  // "eval.KEY=VALUE" rollout settings
  std::string json_path;
};

// Runs and prints everything; true when every run stayed within its bounds (and the precision
// check passed). Throws for unreadable inputs.
bool run_stress(const StressOptions& options);

// One run as JSON (summary figures and per-frame curves), and its verdict for the table: "ok"
// or "FAIL: " and what broke.
nlohmann::json stress_result_json(const StressResult& r);
std::string stress_verdict(const StressResult& r);

}  // namespace layersnet::eval
