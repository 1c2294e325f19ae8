// `layersnet pack --checkpoint C --out F`: a trained model to ship — weights, normalisation
// statistics and the resolved config of a checkpoint, without the optimizer state (Adam's
// moments are twice the weights). Every command that takes --checkpoint reads the result;
// `train --resume` refuses it. --set changes rollout settings (eval.*, the step's conjugate-gradient iterations) in the packed config.
// --average adds checkpoints of the same model whose weights are averaged with the first's
// (e.g. a run's last epochs).
#include "cli/command_registry.h"
#include "cli/model_option.h"
#include "dataset/file_io.h"
#include "dataset/sha256.h"
#include "run/checkpoint.h"

#include <nlohmann/json.hpp>

#include <cstdio>
#include <filesystem>

namespace {

struct PackOptions {
  layersnet::cli::ModelOption model;
  std::string out;
  std::vector<std::string> settings;  // "eval.KEY=VALUE" written into the packed config
  std::vector<std::string> averaged;  // further checkpoints whose weights are averaged in
};

int run_pack(const PackOptions& o) {
  const std::string checkpoint = o.model.required_path();
  std::vector<std::string> sources{checkpoint};
  sources.insert(sources.end(), o.averaged.begin(), o.averaged.end());
  layersnet::LoadedModel m = layersnet::average_models(sources);
  if (!o.settings.empty()) {
    for (const auto& s : o.settings) layersnet::apply_rollout_override(m.config, s);
    m.checkpoint.config_toml = layersnet::to_toml(m.config);
  }
  const std::filesystem::path parent = std::filesystem::path(o.out).parent_path();
  if (!parent.empty()) std::filesystem::create_directories(parent);
  // Provenance beside the model: what it was packed from (hashed before writing, so a model
  // re-packed in place names the file it came from), and the data set it names.
  nlohmann::json prov = {{"model", o.out}, {"sources", nlohmann::json::array()}, {"settings", o.settings}};
  for (const auto& s : sources) prov["sources"].push_back({{"checkpoint", s}, {"sha256", layersnet::io::sha256_file(s)}});
  layersnet::write_checkpoint(o.out, m.params, m.checkpoint);
  prov["model_sha256"] = layersnet::io::sha256_file(o.out);
  const std::filesystem::path manifest = std::filesystem::path(m.config.data.dataset) / "dataset.json";
  prov["dataset"] = m.config.data.dataset;
  prov["dataset_manifest_sha256"] =
      std::filesystem::exists(manifest) ? layersnet::io::sha256_file(manifest.string()) : std::string("not found");
  const std::string prov_path = o.out + ".provenance.json";
  layersnet::io::write_file_atomic(prov_path, prov.dump(1) + "\n");
  if (sources.size() > 1)
    std::printf("weights: the mean of %zu checkpoints (epoch, updates and validation error below are the first's)\n",
                sources.size());
  std::printf("packed %s -> %s (%zu weights, %.2f MB; epoch %lld, %lld updates, best validation error %.6g)\n",
              checkpoint.c_str(), o.out.c_str(), m.params.values().size(),
              static_cast<double>(std::filesystem::file_size(o.out)) / 1e6, static_cast<long long>(m.checkpoint.state.epoch),
              static_cast<long long>(m.checkpoint.state.global_step), m.checkpoint.state.best_val_error);
  std::printf("sha256 %s; provenance in %s\n", prov["model_sha256"].get<std::string>().c_str(), prov_path.c_str());
  return 0;
}

}  // namespace

LAYERSNET_COMMAND(pack, "Write a checkpoint's weights, statistics and config without optimizer state (a model to ship)",
                  [](CLI::App& sub) {
                    auto o = std::make_shared<PackOptions>();
                    o->model.add_to(sub, "checkpoint to pack (e.g. runs/medium/best.h5)");
                    sub.add_option("--out", o->out, "model file to write (e.g. models/medium/model.h5)")->required();
                    sub.add_option("--set", o->settings,
                                   "rollout setting stored with the model, e.g. --set eval.constraints=true (eval.* keys, model.physics_step_cg_iterations and model.physics_step_pins only)");
                    sub.add_option("--average", o->averaged,
                                   "another checkpoint of the same model and data whose weights are averaged with --checkpoint's "
                                   "(repeat it; e.g. a run's last epochs)")
                        ->check(CLI::ExistingFile);
                    return [o] { return run_pack(*o); };
                  });
