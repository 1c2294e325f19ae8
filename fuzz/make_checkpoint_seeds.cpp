// Writes the seed corpus for fuzz_checkpoint: checkpoints of configs/tiny.toml, with and
// without Adam moments and statistics. Usage: make_checkpoint_seeds DIR CONFIG
#include "model/params_layout.h"
#include "run/checkpoint.h"
#include "run/config.h"
#include "run/run_dir.h"

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
    if (variant == 1) {
      layersnet::dataset::NormalisationStats stats;  // mean 0, std 1
      for (auto* q : {&stats.position, &stats.velocity, &stats.acceleration, &stats.root_position,
                      &stats.root_velocity, &stats.root_acceleration})
        q->count = 1;
      cp.stats = layersnet::stats_to_arrays(stats);
    }
    layersnet::write_checkpoint((dir / ("checkpoint" + std::to_string(variant))).string(), params, cp);
  }
  return 0;
}
