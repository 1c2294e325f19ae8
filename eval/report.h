#pragma once
// Reports of an evaluation: written to an output folder
//   eval.json      every number: settings, per method its summary and per-sequence results
//   eval.md        Markdown: summary table (paper Table 3 layout), per garment type (Table 2),
//                  per split T / T+W / L / L+W (Table 1), inner vs outer, error over frames
//   curve.png      error (mm) over the rollout frame, one line per method   (gnuplot)
//   speed.png      error (mm) against ms per frame                          (gnuplot)
//   strain.png     edge strain p99 (%) over the rollout frame, every method (gnuplot)
// and a plain-text summary table for the terminal.
#include "eval/evaluate.h"

#include <nlohmann/json_fwd.hpp>

#include <string>
#include <vector>

namespace layersnet::eval {

struct ReportContext {
  std::string dataset;
  std::string manifest_sha256;      // SHA-256 of the data set's dataset.json (its ids per split)
  EvalConfig post_processing;       // the settings the post-processed baselines ran with
  EvalOptions options;
  double blender_s_per_frame = -1;  // mean over the evaluated sequences; -1 = not recorded
  int speed_frames = 0;             // frames of the speed rollouts
  std::string speed_sequence;       // id of the sequence the speed was measured on
  double load_average = -1;         // 1-minute load average after the run (/proc/loadavg), -1 = unknown
  std::string physics_step_from;    // checkpoint whose step the "one physics step" baseline is; "" = defaults
};

// Where the rollouts start under `options`, for the reports' prose.
std::string start_description(const EvalOptions& options);

// Plain-text table: one row per method (error mm ± std, inner, outer, H %, L %, strain %, ms/frame).
std::string summary_table(const std::vector<MethodResult>& methods, const ReportContext& context);

std::string report_json(const std::vector<MethodResult>& methods, const ReportContext& context);

// The text of a JSON report: one line, every floating-point number to 7 significant digits (what
// float32 results hold; the tables print at most 4), so that reports committed beside a model
// stay small.
std::string report_text(nlohmann::json report);
std::string report_markdown(const std::vector<MethodResult>& methods, const ReportContext& context);

// Writes eval.json, eval.md and (when gnuplot runs) curve.png, speed.png, strain.png into `dir`
// (created). Returns the paths written; a missing gnuplot is reported in eval.md, not thrown.
std::vector<std::string> write_report(const std::string& dir, const std::vector<MethodResult>& methods,
                                      const ReportContext& context);

}  // namespace layersnet::eval
