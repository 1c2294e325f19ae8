#pragma once
// Speed against accuracy over the model knobs: the sweep of `layersnet bench trade`.
//
// One-at-a-time variation around a base config (configs/quick.toml): each variant is
// trained with the same budget (`--budget-epochs`, default: the base config's epochs, so
// every variant sees the same samples) and evaluated, each step a child process of the
// program (`layersnet train ...`, `layersnet eval ...`) so that its peak memory is its
// own (wait4() ru_maxrss) and a crash costs one variant, not the sweep. Results:
//   OUT/variants/<name>/          the run (config, metrics.jsonl, best.h5), train.log,
//                                 eval/ (eval.json ...), eval.log, variant.json (this bench's
//                                 numbers: wall times, peak memory, samples/s)
//   OUT/trade.json, trade.md      every number; the table, the Pareto front, the presets
//   OUT/trade.png                 error against ms/frame (1 thread), front connected (gnuplot)
//   OUT/presets/{fast,balanced,accurate}.toml   `include = "<base>"` + the chosen keys
// Resumable: a variant with variant.json and eval/eval.json is reused; a half-trained run
// continues with `layersnet train --resume`. See eval/README.md "Speed against accuracy".
#include <string>
#include <vector>

namespace layersnet::eval {

struct TradeOptions {
  std::string program;  // the layersnet executable that trains and evaluates each variant
  std::string config = "configs/quick.toml";
  std::string out = "runs/trade";
  std::vector<std::string> variants;   // names; empty = all
  std::vector<std::string> overrides;  // --set for every training
  int budget_epochs = -1;              // -1 = the base config's train.epochs
  int frames = -1, speed_frames = -1, max_sequences = -1, eval_threads = -1;  // -1 = eval's defaults
  double tolerance = 0.20;
  int speed_passes = 3;  // interleaved speed re-measurements of all variants (0 = the per-variant evals' figures)
};

// One point of the sweep: the base config plus `sets`; bf16 = the default variant's
// checkpoint evaluated with bfloat16 matrix products (no training of its own).
struct TradeVariant {
  std::string name, knob, value;
  std::vector<std::string> sets;
  bool bf16 = false;
};

// Every variant, roughly cheapest first.
std::vector<TradeVariant> trade_variants();

// Runs (or reuses) the chosen variants, then the speed passes, and writes the reports;
// progress on stdout. Throws std::runtime_error for an unknown variant name.
void run_trade(const TradeOptions& options);

}  // namespace layersnet::eval
