// `layersnet config`: prints the fully resolved configuration, or every valid key.
#include "cli/command_registry.h"
#include "cli/program_files.h"
#include "run/config.h"

#include <cstdio>
#include <memory>

namespace {

struct ConfigOptions {
  std::vector<std::string> files;
  std::vector<std::string> overrides;
  bool keys = false;
};

int run_config(const ConfigOptions& o) {
  if (o.keys) {
    std::fputs(layersnet::describe_keys().c_str(), stdout);
    return 0;
  }
  const layersnet::Config c = layersnet::load_config(o.files, o.overrides);
  // On stderr: stdout stays the TOML that scripts read.
  for (const auto& w : layersnet::config_warnings(c)) std::fprintf(stderr, "warning: %s\n", w.c_str());
  std::fputs(layersnet::to_toml(c).c_str(), stdout);
  return 0;
}

}  // namespace

LAYERSNET_COMMAND(config, "Print the resolved configuration (defaults < --config files < --set)", [](CLI::App& sub) {
  auto o = std::make_shared<ConfigOptions>();
  sub.add_option("--config,-c", o->files, "TOML config file(s), applied in order (configs/NAME.toml: the program's own when not in the working directory)")
      ->transform([](std::string f) { return layersnet::cli::resolve_user_file(f); });
  sub.add_option("--set", o->overrides, "override one key: --set train.epochs=2");
  sub.add_flag("--keys", o->keys, "list every valid key with its type, default and meaning");
  return [o] { return run_config(*o); };
});
