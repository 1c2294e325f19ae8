// `layersnet`: one program, one subcommand per job (generate, prepare, train, eval, bench, ...).
#include "cli/command_registry.h"
#include "cli/exit_codes.h"
#include "layersnet_version.h"

#include <signal.h>
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <map>
#include <string_view>

namespace layersnet::cli {
std::vector<CommandEntry>& command_registry() {
  static std::vector<CommandEntry> entries;
  return entries;
}
std::vector<CommandEntry>& bench_registry() {
  static std::vector<CommandEntry> entries;
  return entries;
}
}  // namespace layersnet::cli

namespace {
using namespace layersnet::cli;

// Rounds of libgomp's wait loop before an idle thread sleeps, for rollouts: about 1 ms of one
// core per idle gap on the machine measured (docs/decisions.md).
constexpr const char* kRolloutSpinCount = "30000";

bool runs_rollouts(std::string_view command) {
  return command == "simulate" || command == "eval" || command == "stress" || command == "export";
}

void add_entries(CLI::App& parent, std::vector<CommandEntry>& entries, std::map<CLI::App*, CommandAction>& actions) {
  std::sort(entries.begin(), entries.end(), [](const auto& a, const auto& b) { return a.name < b.name; });
  for (auto& entry : entries) {
    CLI::App* sub = parent.add_subcommand(entry.name, entry.description);
    actions[sub] = entry.setup(*sub);
  }
}
}  // namespace

int main(int argc, char** argv) {
  // OpenMP threads that spin at barriers made 2-thread rollouts 10-20x slower than 1 thread
  // (248 vs 25 ms/frame on the default model, even on an idle machine) and collapsed training
  // under load; sleeping waits cost ~12 % of 2-thread training throughput. libgomp reads the
  // policy once, when it loads, so set it and re-execute; an explicit user setting wins.
  // A rollout forks a few hundred short regions a frame, tens of µs apart: a thread that spins a
  // moment before it sleeps is caught awake instead of woken, and a second thread then pays in the
  // network's forward too (docs/decisions.md, "Rollouts' threads spin a moment before they sleep").
  // Training and generation, which run for hours beside other work, keep waits that sleep at once.
  if (!std::getenv("OMP_WAIT_POLICY")) {
    setenv("OMP_WAIT_POLICY", "PASSIVE", 1);
    if (argc > 1 && runs_rollouts(argv[1]) && !std::getenv("GOMP_SPINCOUNT"))
      setenv("GOMP_SPINCOUNT", kRolloutSpinCount, 1);
    execv("/proc/self/exe", argv);  // returns only on failure: then run with the default policy
  }
  // Past a file-size limit (ulimit -f) the kernel kills the writer with SIGXFSZ; ignored, the
  // write fails with EFBIG and the program reports the file like any other failed write.
  signal(SIGXFSZ, SIG_IGN);
  CLI::App app{"LayersNet: learned simulation of multi-layered garments (ICCV 2023), on CPUs", "layersnet"};
  app.footer(kExitCodesHelp);
  app.set_version_flag("--version", std::string("layersnet ") + LAYERSNET_VERSION);
  app.require_subcommand(0, 1);

  std::map<CLI::App*, CommandAction> actions;
  add_entries(app, command_registry(), actions);
  if (!bench_registry().empty()) {
    CLI::App* bench = app.add_subcommand("bench", "Measure speed (ratios against a reference in the same run)");
    bench->require_subcommand(1);
    add_entries(*bench, bench_registry(), actions);
  }

  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    const int code = app.exit(e);  // prints the help, the version or CLI11's message
    return code == 0 ? kExitOk : kExitUsage;
  }
  for (auto& [sub, action] : actions) {
    if (sub->parsed()) {
      try {
        return action();
      } catch (const UsageError& e) {
        std::fprintf(stderr, "layersnet %s: %s\n", sub->get_name().c_str(), e.what());
        return kExitUsage;
      } catch (const std::exception& e) {
        // The one error report of every subcommand: name the command, then the message.
        std::fprintf(stderr, "layersnet %s: error: %s\n", sub->get_name().c_str(), e.what());
        return kExitError;
      }
    }
  }
  std::fputs(app.help().c_str(), stdout);
  return 0;
}
