#pragma once
// `layersnet eval` as one call: every checkpoint (and run) as a model predictor, once per
// cloth-constraint setting, patch tether and product precision asked for, recorded sequences
// (Replay), the baselines (each bare and, when a model runs with it, with the same
// post-processing) and the ground truth, evaluated over a split (evaluate.h); speed
// at 1 and 2 threads on the split's first sequence, Blender's recorded time, and the reports
// (report.h: eval.json, eval.md, plots) with the summary table printed.
#include "autodiff/bf16_gemm.h"

#include <string>
#include <vector>

namespace layersnet::eval {

struct EvalRunOptions {
  std::vector<std::string> runs;         // run directories (their run_checkpoint), before the checkpoints
  std::vector<std::string> checkpoints;
  std::vector<std::string> names;        // of each model, then of each replay; default: folder/file
  std::vector<std::string> replays;      // folders of recorded sequences (Replay)
  std::string dataset;                   // empty: the first checkpoint's data.dataset
  std::string split;                     // empty: the config's eval.split
  int frames = -1;                       // <= 0: the config's eval.frames
  int mark_frames = 36;                  // EvalOptions::mark_frames
  int start_frame = -1;
  std::string start;                     // ramp | fixed; empty: ramp, or fixed when start_frame is given
  int max_sequences = 0;
  std::vector<std::string> sequences;    // EvalOptions::sequences
  double wind_scale = 1.0;               // EvalOptions::wind_scale
  std::string wind_twins;                // EvalOptions::wind_twins
  bool mirror = false;                   // EvalOptions::mirror
  bool rig_pins = false;                 // EvalOptions::rig_pins
  int speed_frames = 10;
  std::string out = "eval_out";
  std::vector<ad::MatmulPrecision> precisions = {ad::MatmulPrecision::kFloat32};  // every model once per entry
  std::string precision_label = "float32";  // as the user wrote it, for the header line
  std::vector<double> tethers;           // patch tether factors; empty: each checkpoint's own
  std::vector<std::string> constraints;  // "on" / "off"; empty: each checkpoint's own
  std::vector<std::string> settings;     // "eval.KEY=VALUE" for every model
};

// Runs everything above; progress and the summary table on stdout. Throws for unreadable inputs.
void run_evaluation(EvalRunOptions options);

}  // namespace layersnet::eval
