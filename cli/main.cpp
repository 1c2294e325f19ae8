// `layersnet`: one program, one subcommand per job (generate, prepare, train, eval, bench, ...).
#include "cli/command_registry.h"
#include "layersnet_version.h"

#include <algorithm>
#include <cstdio>
#include <exception>
#include <map>

namespace layersnet::cli {
std::vector<CommandEntry>& command_registry() {
  static std::vector<CommandEntry> entries;
  return entries;
}
}  // namespace layersnet::cli

int main(int argc, char** argv) {
  using namespace layersnet::cli;
  CLI::App app{"LayersNet: learned simulation of multi-layered garments (ICCV 2023), on CPUs", "layersnet"};
  app.set_version_flag("--version", std::string("layersnet ") + LAYERSNET_VERSION);
  app.require_subcommand(0, 1);

  auto& entries = command_registry();
  std::sort(entries.begin(), entries.end(), [](const auto& a, const auto& b) { return a.name < b.name; });
  std::map<CLI::App*, CommandAction> actions;
  for (auto& entry : entries) {
    CLI::App* sub = app.add_subcommand(entry.name, entry.description);
    actions[sub] = entry.setup(*sub);
  }

  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  }
  for (auto& [sub, action] : actions) {
    if (sub->parsed()) {
      try {
        return action();
      } catch (const std::exception& e) {
        std::fprintf(stderr, "layersnet %s: error: %s\n", sub->get_name().c_str(), e.what());
        return 1;
      }
    }
  }
  std::fputs(app.help().c_str(), stdout);
  return 0;
}
