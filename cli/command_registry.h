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
// The setup function adds options to `sub` and returns the action to run when the
// subcommand is chosen; the action's return value is the process exit code.
#include <CLI/CLI.hpp>

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

struct CommandRegistrar {
  CommandRegistrar(std::string name, std::string description, CommandSetup setup) {
    command_registry().push_back({std::move(name), std::move(description), std::move(setup)});
  }
};

}  // namespace layersnet::cli

#define LAYERSNET_COMMAND(name, description, setup_fn) \
  static ::layersnet::cli::CommandRegistrar layersnet_command_registrar_##name(#name, description, setup_fn)
