// `layersnet train --config F [--set k=v ...] [--run DIR]` and `layersnet train --resume DIR`.
#include "cli/command_registry.h"
#include "cli/exit_codes.h"
#include "cli/program_files.h"
#include "autodiff/arena.h"
#include "train/distributed.h"
#include "train/trainer.h"

#include <filesystem>
#include <iostream>
#include <memory>
#include <sstream>

namespace {

struct TrainCliOptions {
  std::vector<std::string> files;
  std::vector<std::string> overrides;
  std::string run;
  std::string resume;
};

int run_train_here(const TrainCliOptions& o, std::ostream& err) {
  layersnet::TrainOptions options;
  layersnet::Config config;
  if (!o.resume.empty()) {
    if (!o.files.empty()) {
      err << "error: --resume " << o.resume << " continues with the run's own config.toml; drop --config "
                << "(use --set key=value to change e.g. train.epochs)\n";
      return layersnet::cli::kExitUsage;
    }
    if (!o.run.empty() && std::filesystem::path(o.run) != std::filesystem::path(o.resume)) {
      err << "error: --run and --resume name different directories\n";
      return layersnet::cli::kExitUsage;
    }
    config = layersnet::run_config(o.resume, o.overrides);
    options.run_dir = o.resume;
    options.resume = true;
  } else {
    if (o.files.empty()) {
      err << "error: give --config FILE (e.g. configs/default.toml) or --resume DIR\n";
      return layersnet::cli::kExitUsage;
    }
    config = layersnet::load_config(o.files, o.overrides);
    options.run_dir = o.run.empty() ? "runs/" + std::filesystem::path(o.files.back()).stem().string() : o.run;
  }
  try {
    const auto s = layersnet::train(config, options);
    if (layersnet::Ranks::world().rank() != 0) return 0;  // rank 0 reports for the job
    std::cout << "done: " << s.updates << " updates";
    if (s.best_val_error >= 0) std::cout << ", best validation error " << s.best_val_error;
    std::cout << "; last checkpoint " << s.last_checkpoint << "\n";
    return 0;
  } catch (const layersnet::TrainingStopped& e) {
    if (layersnet::Ranks::world().rank() == 0) std::cerr << "training stopped: " << e.what() << "\n";
    return layersnet::cli::kExitTrainingStopped;
  }
}

int run_train(const TrainCliOptions& o) {
  layersnet::ad::keep_freed_memory_in_process();
  const layersnet::Ranks& ranks = layersnet::Ranks::world();
  if (!ranks.distributed()) return run_train_here(o, std::cerr);
  // Under mpirun every rank parses the same arguments: a refusal is reported once (by rank 0
  // when it fails too) and ends the whole job, so no rank waits for one that left.
  std::ostringstream err;
  try {
    const int code = run_train_here(o, err);
    if (code == layersnet::cli::kExitUsage) {
      std::string text = err.str();
      if (text.rfind("error: ", 0) == 0) text = text.substr(7);
      while (!text.empty() && text.back() == '\n') text.pop_back();
      ranks.abort_job(text, code);
    }
    return code;
  } catch (const layersnet::cli::UsageError& e) {
    ranks.abort_job(e.what(), layersnet::cli::kExitUsage);
  } catch (const std::exception& e) {
    ranks.abort_job(e.what(), layersnet::cli::kExitError);
  }
}

}  // namespace

LAYERSNET_COMMAND(train, "Train a model from a config file (checkpoints, exact --resume)", [](CLI::App& sub) {
  auto o = std::make_shared<TrainCliOptions>();
  sub.add_option("--config,-c", o->files, "TOML config file(s), applied in order (configs/NAME.toml: the program's own when not in the working directory)")
      ->transform([](std::string f) { return layersnet::cli::resolve_user_file(f); });
  sub.add_option("--set", o->overrides, "override one key: --set train.epochs=2");
  sub.add_option("--run", o->run, "run directory (default runs/<config name>); must not hold a run yet");
  sub.add_option("--resume", o->resume, "continue the run in this directory from its newest checkpoint");
  return [o] { return run_train(*o); };
});
