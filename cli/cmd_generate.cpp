// `layersnet generate`: makes a D-LAYERS-like data set with Blender's cloth solver
// (the driver: dataset/generate.h). Finds the script, recipe and checker that ship with the program.
#include "cli/command_registry.h"
#include "cli/program_files.h"
#include "dataset/generate.h"

#include <memory>
#include <string>

namespace {

using layersnet::dataset::GenerateError;

std::string find_script(const std::string& given) {
  if (!given.empty()) return given;
  const std::filesystem::path found = layersnet::cli::find_program_file("generate/make_sequence.py");
  if (found.empty())
    throw GenerateError("generate/make_sequence.py not found in " + layersnet::cli::program_files_dir().string() +
                        " (where the program's files are installed) or the working directory; pass --script PATH");
  return found.string();
}

int run_generate(layersnet::dataset::GenerateOptions o) {
  o.script = find_script(o.script);
  if (o.recipe.empty()) o.recipe = (std::filesystem::path(find_script("")).parent_path() / "recipes/default.json").string();
  if (o.checker.empty()) o.checker = layersnet::cli::find_program_file("dataset/check_dlayers_h5.py").string();
  return layersnet::dataset::generate_dataset(o).accepted > 0 ? 0 : 1;
}

}  // namespace

LAYERSNET_COMMAND(generate, "Simulate D-LAYERS-like sequences with Blender's cloth solver", [](CLI::App& sub) {
  auto opt = std::make_shared<layersnet::dataset::GenerateOptions>();
  sub.add_option("--out", opt->out, "data set folder to write (created; existing accepted sequences are kept)")->required();
  sub.add_option("--recipe", opt->recipe, "recipe JSON (default: generate/recipes/default.json)");
  sub.add_option("--count", opt->count, "number of sequences (overrides the recipe)");
  sub.add_option("--frames", opt->frames, "frames per sequence at 30 fps (overrides the recipe)");
  sub.add_option("--seed", opt->seed, "data set seed (overrides the recipe)");
  sub.add_option("--max-attempts", opt->max_attempts, "simulations per sequence before it is dropped");
  sub.add_option("--threads", opt->threads, "Blender threads per Blender process");
  sub.add_option("--jobs", opt->jobs, "Blender processes at once (results do not depend on it)")->check(CLI::PositiveNumber);
  sub.add_option("--manifest-every", opt->manifest_every,
                 "rewrite dataset.json after every this many finished sequences (0: only at the end)");
  sub.add_option("--blender", opt->blender, "Blender executable");
  sub.add_option("--script", opt->script, "path of generate/make_sequence.py");
  sub.add_option("--splits", opt->only_splits,
                 "simulate only these splits (e.g. val,test); other splits' existing sequences are kept")
      ->delimiter(',')
      ->check(CLI::IsMember({"train", "val", "test"}));
  sub.add_option("--train-limit", opt->train_limit,
                 "simulate only the first N training sequences (by index); the others are left for a later run")
      ->check(CLI::NonNegativeNumber);
  sub.add_option("--checker", opt->checker, "validator run on each accepted file (default: dataset/check_dlayers_h5.py)");
  return [opt] { return run_generate(*opt); };  // errors: reported by cli/main.cpp
});
