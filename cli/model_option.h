#pragma once
// The model a command reads, named one of two ways: `--checkpoint FILE` or `--run DIR` (a
// `layersnet train` run: its best.h5, else its newest checkpoint). The checkpoint carries the
// resolved config, so either way the command learns the patch size and every other setting
// from the model itself and has no default of its own.
#include "cli/exit_codes.h"
#include "run/run_dir.h"

#include <CLI/CLI.hpp>

#include <memory>
#include <string>

namespace layersnet::cli {

struct ModelOption {
  std::string checkpoint;
  std::string run;

  // Registers both options (mutually exclusive) on `sub`.
  void add_to(CLI::App& sub, const std::string& checkpoint_help) {
    CLI::Option* c = sub.add_option("--checkpoint", checkpoint, checkpoint_help);
    CLI::Option* r = sub.add_option("--run", run, "run directory of `layersnet train` instead (its best.h5, else its newest checkpoint)");
    c->excludes(r);
  }
  bool given() const { return !checkpoint.empty() || !run.empty(); }
  // The checkpoint file; throws when `--run` names no run with a checkpoint.
  std::string path() const { return run.empty() ? checkpoint : run_checkpoint(run); }
  // The same, for a command that cannot run without a model.
  std::string required_path() const {
    if (!given()) throw UsageError("give the model: --checkpoint FILE or --run DIR");
    return path();
  }
};

}  // namespace layersnet::cli
