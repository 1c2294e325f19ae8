#pragma once
// The synthetic scene the physics-energy tests share: two tube layers with wind, 8 frames.
#include "dataset/synthetic.h"

namespace layersnet::losses::testing {

inline dataset::Sequence two_layers_with_wind() {
  dataset::SyntheticOptions o;
  o.garments = 2;
  o.wind = true;
  o.frames = 8;
  return dataset::make_synthetic_sequence(o);
}

}  // namespace layersnet::losses::testing
