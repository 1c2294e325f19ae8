// `layersnet pack --checkpoint C --out F`: a trained model to ship — weights, normalisation
// statistics and the resolved config of a checkpoint, without the optimizer state (Adam's
// moments are twice the weights). Every command that takes --checkpoint reads the result;
// `train --resume` refuses it. --set changes rollout settings (eval.*) in the packed config.
#include "cli/command_registry.h"
#include "cli/model_option.h"
#include "run/checkpoint.h"

#include <cstdio>
#include <filesystem>

namespace {

struct PackOptions {
  layersnet::cli::ModelOption model;
  std::string out;
  std::vector<std::string> settings;  // "eval.KEY=VALUE" written into the packed config
};

int run_pack(const PackOptions& o) {
  const std::string checkpoint = o.model.required_path();
  layersnet::LoadedModel m = layersnet::load_model(checkpoint);
  m.checkpoint.has_optimizer = false;
  m.checkpoint.state.rng.clear();
  if (!o.settings.empty()) {
    for (const auto& s : o.settings) layersnet::apply_rollout_override(m.config, s);
    m.checkpoint.config_toml = layersnet::to_toml(m.config);
  }
  const std::filesystem::path parent = std::filesystem::path(o.out).parent_path();
  if (!parent.empty()) std::filesystem::create_directories(parent);
  layersnet::write_checkpoint(o.out, m.params, m.checkpoint);
  std::printf("packed %s -> %s (%zu weights, %.2f MB; epoch %lld, %lld updates, best validation error %.6g)\n",
              checkpoint.c_str(), o.out.c_str(), m.params.values().size(),
              static_cast<double>(std::filesystem::file_size(o.out)) / 1e6, static_cast<long long>(m.checkpoint.state.epoch),
              static_cast<long long>(m.checkpoint.state.global_step), m.checkpoint.state.best_val_error);
  return 0;
}

}  // namespace

LAYERSNET_COMMAND(pack, "Write a checkpoint's weights, statistics and config without optimizer state (a model to ship)",
                  [](CLI::App& sub) {
                    auto o = std::make_shared<PackOptions>();
                    o->model.add_to(sub, "checkpoint to pack (e.g. runs/medium/best.h5)");
                    sub.add_option("--out", o->out, "model file to write (e.g. models/medium/model.h5)")->required();
                    sub.add_option("--set", o->settings,
                                   "rollout setting stored with the model, e.g. --set eval.constraints=true (eval.* keys only)");
                    return [o] { return run_pack(*o); };
                  });
