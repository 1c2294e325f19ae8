#pragma once
// dataset::TrainingSample (the sample builder of dataset/sample.h) -> ModelInput<float>.
//
// The sample already holds root-relative normalised states, patch structure, world edges,
// body neighbours and nearest body vertices; this adds what only the model needs:
//   body tokens   the body vertices some patch, patch centre or vertex refers to (U rows),
//                 their normalised states and normal frames (at t+1);
//   body lists    valid slots only, each body vertex at most once per patch (the
//                 official duplicate padding is dropped, model/README.md quirk 3);
//   gravity token [g(t+1), g(t), root motion (t+1), root motion (t)] (18) and the frame of
//                 the raw direction g/fps − root_acc(t) (needs the statistics to undo the
//                 normalisation);
//   decoder       nearest body within R_b (else -1) and the candidate patches.
// Body query order (nearest / first K) is the sample's (dataset SampleOptions); build the
// samples with sample_options_for(config).
#include "dataset/sample.h"
#include "dataset/stats.h"
#include "model/model_config.h"
#include "model/model_input.h"

#include <cstdint>
#include <vector>

namespace layersnet::model {

ModelInput<float> model_input_from_sample(const dataset::TrainingSample& sample, const dataset::NormalisationStats& stats,
                                          const ModelConfig& config);

// Sample options matching the model config (patch size, radii, K, body query; no duplicate
// padding): what build_sample needs for model_input_from_sample.
dataset::SampleOptions sample_options_for(const ModelConfig& model);

// The official frame of a normal (utils/mesh3d.py) for the unit direction of `normal`:
// R = rows [x; y; n] (world -> local, n -> e_z), x from (1,0,0) with the |n_c| < 1e-7 rule.
// A zero vector gives the identity. R: 9 numbers, row-major.
void normal_frame(const double normal[3], double R[9]);

// Decoder candidates (official patch_decoder.py): for each vertex, the k nearest (to x_t) patches
// mesh-adjacent to its own patch, kept if own, or closer to the vertex than to the own
// patch's centre. xt (N, 3), centre (P, 3), own_patch (N), adjacency CSR over P -> CSR over N.
void decoder_candidates(const std::vector<double>& xt, const std::vector<double>& centre,
                        const std::vector<int32_t>& own_patch, const std::vector<int32_t>& adj_offsets,
                        const std::vector<int32_t>& adj_patches, int k, std::vector<int32_t>& offsets,
                        std::vector<int32_t>& items);

}  // namespace layersnet::model
