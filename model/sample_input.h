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
// samples with neighbours.body_query matching ModelConfig::body_query.
#include "dataset/sample.h"
#include "dataset/stats.h"
#include "model/model_config.h"
#include "model/model_input.h"

namespace layersnet::model {

ModelInput<float> model_input_from_sample(const dataset::TrainingSample& sample, const dataset::NormalisationStats& stats,
                                          const ModelConfig& config);

}  // namespace layersnet::model
