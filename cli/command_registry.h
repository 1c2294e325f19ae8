#pragma once
// Subcommands of `layersnet` register themselves from their own cmd_<name>.cpp:
//
//   static int run_inspect(const InspectOptions&);
//   LAYERSNET_COMMAND(inspect, "Summarise a data set", [](CLI::App& sub) {
//     auto opts = std::make_shared<InspectOptions>();
//     sub.add_option("dataset", opts->root, "data set folder")->required();
//     return [opts] { return run_inspect(*opts); };
//   });
//
// LAYERSNET_BENCH(linear, ...) registers `layersnet bench linear` the same way.
//
// The setup function adds options to `sub` and returns the action to run when the
// subcommand is chosen; the action's return value is the process exit code.
#include <CLI/CLI.hpp>

#include <cmath>
#include <functional>
#include <string>
#include <vector>

namespace layersnet::cli {

using CommandAction = std::function<int()>;
using CommandSetup = std::function<CommandAction(CLI::App& sub)>;

struct CommandEntry {
  std::string name;
  std::string description;
  CommandSetup setup;
};

// Registered commands, sorted by name when --help lists them.
std::vector<CommandEntry>& command_registry();
// Benchmarks, listed under `layersnet bench <name>`.
std::vector<CommandEntry>& bench_registry();

// Option check: a finite number >= 0 (CLI::NonNegativeNumber lets "nan" through).
inline const CLI::Validator kFiniteNonNegative(
    [](std::string& text) -> std::string {
      double value = 0;
      if (!CLI::detail::lexical_cast(text, value) || !std::isfinite(value) || value < 0)
        return "'" + text + "' is not a finite number >= 0";
      return {};
    },
    "FINITE>=0");

struct CommandRegistrar {
  CommandRegistrar(std::vector<CommandEntry>& registry, std::string name, std::string description,
                   CommandSetup setup) {
    registry.push_back({std::move(name), std::move(description), std::move(setup)});
  }
};

}  // namespace layersnet::cli

#define LAYERSNET_COMMAND(name, description, setup_fn)                                              \
  static ::layersnet::cli::CommandRegistrar layersnet_command_registrar_##name(                     \
      ::layersnet::cli::command_registry(), #name, description, setup_fn)

// Same, for a benchmark run as `layersnet bench <name>`.
#define LAYERSNET_BENCH(name, description, setup_fn)                                                \
  static ::layersnet::cli::CommandRegistrar layersnet_bench_registrar_##name(                       \
      ::layersnet::cli::bench_registry(), #name, description, setup_fn)
