// Writes the seed corpus for fuzz_checkpoint: checkpoints of configs/tiny.toml, with and
// without Adam moments and statistics. Usage: make_checkpoint_seeds DIR CONFIG
#include "model/params_layout.h"
#include "train/checkpoint.h"
#include "train/config.h"

#include <filesystem>

int main(int argc, char** argv) {
  if (argc != 3) return 2;
  const std::filesystem::path dir = argv[1];
  std::filesystem::create_directories(dir);
  const layersnet::Config config = layersnet::load_config({argv[2]});
  for (int variant = 0; variant < 2; ++variant) {
    layersnet::ad::ParamStore<float> params;
    layersnet::model::register_params(params, config.model);
    layersnet::model::init_params(params, config.model, 7 + variant);
    layersnet::Checkpoint cp;
    cp.config_toml = layersnet::to_toml(config);
    cp.has_optimizer = variant == 1;
    if (variant == 1)
      for (const char* q : {"position", "velocity", "acceleration", "root_position", "root_velocity", "root_acceleration"}) {
        cp.stats[std::string(q) + ".mean"] = {0.0, 0.0, 0.0};
        cp.stats[std::string(q) + ".std"] = {1.0, 1.0, 1.0};
        cp.stats[std::string(q) + ".count"] = {1.0};
      }
    layersnet::write_checkpoint((dir / ("checkpoint" + std::to_string(variant))).string(), params, cp);
  }
  return 0;
}
