#pragma once
// A small synthetic scene for tests and benchmarks: up to two cylindrical garment grids
// (inner, outer) around a bumpy cylindrical "body", with smooth motion fields, a moving
// root, optional wind, patches from grid cells (the official patchwise rule on a regular
// UV grid) and statistics measured on the scene itself. Deterministic for a seed.
#include "model/scene.h"

#include <array>
#include <cstdint>
#include <vector>

namespace layersnet::model {

struct SyntheticSceneOptions {
  // Garment grids (around, along) in vertices; one entry per garment, inner first.
  std::vector<std::array<int, 2>> garments = {{12, 8}, {14, 8}};
  std::array<int, 2> body = {16, 10};  // body grid (around, along), closed around
  std::array<int, 2> cell = {3, 3};    // patch = cell of quads (around, along)
  double spacing = 0.1;                // garment vertex spacing, scene units
  // Geometry (scene units). Empty radius / z0 lists: defaults 1.05 + 0.05 g and -0.05 g.
  std::vector<double> garment_radius;  // nominal radius of garment g (its grid wraps by spacing / radius)
  std::vector<double> garment_z0;      // height of garment g's first row
  double body_radius = 1.0;            // body cylinder radius
  std::array<double, 2> body_z = {-0.3, 1.1};  // body height range
  bool wind = true;
  double root_offset[3] = {0, 0, 0};   // added to every world position (and the root)
  uint64_t seed = 1;
};

SceneWindow make_synthetic_scene(const SyntheticSceneOptions& options);

}  // namespace layersnet::model
