#pragma once
// A small, deterministic synthetic scene for tests, benchmarks and examples:
//   body     a cylinder (outward faces, capped or open-ended) translating on a sine path;
//   garments 1..3 open tubes around it ("tee", "jacket", ...), each cut into 2 UV panels
//            (front and back halves; the seam vertices are shared in 3-D, UVs per corner),
//            or open cylindrical sheets of a given grid (one UV panel each), any number;
//            both follow the body with a lag and ripple (a sheet about its mid-height);
//   wind     optional, piecewise constant: none, then two segments of different direction.
// Units: scene units (scale 10 per metre, as D-LAYERS), z up, gravity (0, 0, -9.8).
// Garment g's geometry, motion and attributes do not depend on the garments after it, and
// neither body nor garments depend on the wind: fewer garments or no wind give the same
// sequence minus that part (bit-identical), which the cost benchmarks rely on.
#include "dataset/manifest.h"
#include "dataset/sequence.h"

#include <array>
#include <cstdint>
#include <string>
#include <vector>

namespace layersnet::dataset {

// An open cylindrical sheet: `around` x `along` vertices, SyntheticOptions::sheet_spacing apart
// (around the cylinder of `radius` and up from height z0), two triangles per grid quad. Its
// one UV panel puts vertex (i, j) at (i uv_step[0], j uv_step[1]), so a patch of size s holds
// s / uv_step quads per side (e.g. step 0.04 / 3: 3 x 3 quads at the default 0.04).
struct SyntheticSheet {
  int around = 10;
  int along = 6;
  float radius = 1.5f;  // scene units
  float z0 = 0.f;       // height of the first row, scene units
  std::array<float, 2> uv_step = {0.04f / 3, 0.04f / 3};  // UV units per grid step (around, along)
};

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
  float height = 4.0f;        // body height; a tube spans 0.8 of it from z = 0
  float uv_per_unit = 0.05f;  // UV units per scene unit (0.04 UV = 0.8 units)
  float body_bottom = -0.2f;  // height of the body's first row; its last is at body_bottom + height
  bool body_caps = true;     // close the body's ends (one centre vertex each)
  bool wind = false;
  float motion = 0.3f;       // amplitude of the body's sine translation (scene units)
  uint64_t seed = 1;         // varies attributes and a small ripple
  // Sheets instead of tubes: when not empty, the garments are these, inner first
  // (`garments`, `rings`, `segments`, `radius`, `layer_gap`, `uv_per_unit` then do not apply).
  std::vector<SyntheticSheet> sheets;
  float sheet_spacing = 0.1f;  // scene units between grid neighbours
  // Added to every position and to the root translation: the same scene elsewhere in the world.
  std::array<float, 3> offset = {0.f, 0.f, 0.f};
  // Added to the body only (not the root): a body away from the garments.
  std::array<float, 3> body_offset = {0.f, 0.f, 0.f};
};

Sequence make_synthetic_sequence(const SyntheticOptions& options = {});

// Writes <root>/dataset.json and n_train + n_val + n_test synthetic sequences named
// s0000, s0001, ... (seed = options.seed + index; every second one with wind if
// options.wind). Returns the manifest.
DatasetManifest write_synthetic_dataset(const std::string& root, int n_train, int n_val, int n_test,
                                        const SyntheticOptions& options = {},
                                        const SequenceWriteOptions& write_options = {});

}  // namespace layersnet::dataset
