// `layersnet bench trade`: speed against accuracy over the model knobs (the sweep:
// bench/trade.h). Every variant is trained and evaluated by a child process of this program.
#include "cli/command_registry.h"
#include "cli/program_files.h"
#include "bench/trade.h"

#include <unistd.h>

#include <cstdio>
#include <memory>
#include <string>

namespace {

struct TradeCli {
  layersnet::eval::TradeOptions options;
  bool list = false;
};

int list_variants() {
  for (const auto& v : layersnet::eval::trade_variants()) {
    std::printf("%-11s %s\n", v.name.c_str(), v.bf16 ? "default checkpoint, eval --precision bf16" : "");
    for (const auto& s : v.sets) std::printf("            --set %s\n", s.c_str());
  }
  return 0;
}

}  // namespace

LAYERSNET_BENCH(trade, "Train and evaluate model variants (patch, width, layers, K, candidates, bf16): error vs speed, Pareto front, presets",
                [](CLI::App& sub) {
                  auto args = std::make_shared<TradeCli>();
                  layersnet::eval::TradeOptions* o = &args->options;
                  sub.add_option("--config,-c", o->config, "base config (default configs/quick.toml)");
                  sub.add_option("--out", o->out, "output folder (default runs/trade); rerunning reuses finished variants");
                  sub.add_option("--variants", o->variants, "variants to run, comma separated (default: all; --list shows them)")
                      ->delimiter(',');
                  sub.add_option("--budget-epochs", o->budget_epochs, "training epochs of every variant (default: the base config's)");
                  sub.add_option("--set", o->overrides, "extra override for every training, e.g. --set train.threads=2");
                  sub.add_option("--frames", o->frames, "eval: predicted frames per sequence (default: the config's eval.frames)");
                  sub.add_option("--speed-frames", o->speed_frames, "eval: frames of the speed rollouts (default 10)");
                  sub.add_option("--max-sequences", o->max_sequences, "eval: first N sequences of the split (0 = all)");
                  sub.add_option("--eval-threads", o->eval_threads, "eval: threads of the accuracy rollouts (speed is always 1 and 2)");
                  sub.add_option("--tolerance", o->tolerance, "fast preset: error within (1 + tolerance) x the default's (default 0.20)");
                  sub.add_option("--speed-passes", o->speed_passes,
                                 "after the sweep, measure the speed of all variants back to back this many times and keep "
                                 "each one's fastest (0 = each variant's own eval figure)");
                  sub.add_flag("--list", args->list, "list the variants and exit");
                  return [args] {
                    if (args->list) return list_variants();
                    layersnet::eval::TradeOptions* o = &args->options;
                    o->config = layersnet::cli::resolve_user_file(o->config);  // the default too
                    // /proc/<pid>/exe: still this program when its file is rebuilt during a sweep.
                    o->program = "/proc/" + std::to_string(::getpid()) + "/exe";
                    layersnet::eval::run_trade(*o);
                    return 0;
                  };
                });
