#pragma once
// Shared fixtures for the model tests: a tiny configuration and synthetic scenes.
#include "model/input_builder.h"
#include "model/model_config.h"
#include "model/synthetic_scene.h"

namespace layersnet::model::testing {

// Small enough for a double-precision whole-model gradient check in well under a second.
inline ModelConfig tiny_config() {
  ModelConfig c;
  c.width = 16;
  c.heads = 4;
  c.layers = 2;
  c.ffn_width = 24;
  c.decoder_width = 20;
  c.body_neighbors = 4;
  c.decoder_ret_channels = 4;  // 3k <= width
  return c;
}

inline SyntheticSceneOptions tiny_scene(bool wind = true, int garments = 2) {
  SyntheticSceneOptions o;
  o.garments = {{9, 6}, {10, 6}};
  o.garments.resize(garments);
  o.body = {12, 8};
  o.cell = {3, 3};
  o.wind = wind;
  return o;
}

}  // namespace layersnet::model::testing
