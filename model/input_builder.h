#pragma once
// SceneWindow (world coordinates) -> ModelInput (root-relative, normalised, neighbour lists,
// frames): all the non-differentiable preparation of one forward, done outside the tape.
//
// What is computed (as the official code; decisions in model/README.md):
//   states         [x_t, v_t, x_{t-1}, v_{t-1}] minus the root translation of each frame;
//                  body [x_{t+1}, v_{t+1}, x_t, v_t] likewise; normalised with the stats.
//   patch states   mean of member vertex states (raw and normalised).
//   world edges    patch centres (t) closer than R, minus mesh-adjacent patches; no cap.
//   body edges     per patch up to K body vertices (t+1) within R_b: the K nearest
//                  (config body_query "nearest") or the first K in index order ("first",
//                  official ball query) — without the official duplicate padding.
//   body frames    rotation_from_normals of the body vertex normals at t+1.
//   decoder        nearest body vertex (t+1) of each patch centre / vertex (x_t) if < R_b;
//                  the 4 nearest mesh-adjacent patches of the own patch that pass the
//                  official validity test.
//   wind, gravity  wind token only when the scene has wind; gravity token always, carrying
//                  the root motion too.
// Neighbourhoods use the data layer's structures (dataset/neighbours.h: hash grid for world
// and body edges, k-d tree for nearest body vertices, its vertex normals), the same code as
// the dataset path, never all-pairs loops; the searches run on float copies.
#include "model/model_config.h"
#include "model/model_input.h"
#include "model/scene.h"

namespace layersnet::model {

ModelInput<double> build_model_input(const SceneWindow& scene, const ModelConfig& config);

// Official rotation_from_normals (utils/mesh3d.py) of the unit direction of `normal`:
// R = rows [x; y; n] (world -> local, n -> e_z), x from (1,0,0) with the |n_c| < 1e-7 rule.
// A zero vector gives the identity.
void normal_frame(const double normal[3], double R[9]);

// Decoder candidates (official patch_decoder.py): for each vertex, the k nearest (to x_t) patches
// mesh-adjacent to its own patch, kept if own, or closer to the vertex than to the own
// patch's centre. xt (N, 3), centre (P, 3), own_patch (N), adjacency CSR over P -> CSR over N.
void decoder_candidates(const std::vector<double>& xt, const std::vector<double>& centre,
                        const std::vector<int32_t>& own_patch, const std::vector<int32_t>& adj_offsets,
                        const std::vector<int32_t>& adj_patches, int k, std::vector<int32_t>& offsets,
                        std::vector<int32_t>& items);

// 3x3 rotation (row-major, 9 numbers) of a unit quaternion (w, x, y, z); an all-zero
// quaternion gives the identity (as the official wind reader).
void quaternion_to_rotation(const double q[4], double R[9]);

// Normalised sum of incident unit face normals, face normal (v1 - v0) x (v2 - v0).
// x: (V, 3), faces: (F, 3) -> (V, 3). A vertex without a usable face gets (0, 0, 1).
std::vector<double> vertex_normals(const std::vector<double>& x, const std::vector<int32_t>& faces);

// Index of the nearest row of `ref` (M, 3) for every row of `query` (Q, 3), and its distance
// (k-d tree search in float, distance recomputed in double).
void nearest_points(const std::vector<double>& query, const std::vector<double>& ref, std::vector<int32_t>& index,
                    std::vector<double>& distance);

}  // namespace layersnet::model
