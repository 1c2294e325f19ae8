#pragma once
// A small, deterministic synthetic scene for tests, benchmarks and examples:
//   body     a closed capped cylinder (outward faces) translating on a sine path;
//   garments 1..3 open tubes around it ("tee", "jacket", ...), each cut into 2 UV panels
//            (front and back halves; the seam vertices are shared in 3-D, UVs per corner);
//   wind     optional, piecewise constant: none, then two segments of different direction.
// Units: scene units (scale 10 per metre, as D-LAYERS), z up, gravity (0, 0, -9.8).
#include "dataset/manifest.h"
#include "dataset/sequence.h"

#include <cstdint>
#include <string>

namespace layersnet::dataset {

struct SyntheticOptions {
  int frames = 8;            // T
  int garments = 1;          // number of tube garments (1..3), inner to outer
  int rings = 6;             // vertex rows of each tube along its height
  int segments = 16;         // vertices around a tube (even; half per panel)
  int body_rings = 6;        // body cylinder rows
  int body_segments = 16;    // body cylinder vertices per row
  float radius = 1.5f;       // radius of the innermost tube (scene units)
  float layer_gap = 0.25f;   // radius step between garment layers
  float body_radius = 1.2f;
  float height = 4.0f;
  float uv_per_unit = 0.05f;  // UV units per scene unit (0.04 UV = 0.8 units)
  bool wind = false;
  float motion = 0.3f;       // amplitude of the body's sine translation (scene units)
  uint64_t seed = 1;         // varies attributes and a small ripple
};

Sequence make_synthetic_sequence(const SyntheticOptions& options = {});

// Writes <root>/dataset.json and n_train + n_val + n_test synthetic sequences named
// s0000, s0001, ... (seed = options.seed + index; every second one with wind if
// options.wind). Returns the manifest.
DatasetManifest write_synthetic_dataset(const std::string& root, int n_train, int n_val, int n_test,
                                        const SyntheticOptions& options = {},
                                        const SequenceWriteOptions& write_options = {});

}  // namespace layersnet::dataset
