#pragma once
// How samples are cut for a model: the one place that turns a config into the data layer's
// sample options, used by training, evaluation, stress runs and `inspect` alike.
#include "dataset/sample.h"
#include "run/config.h"

namespace layersnet {

// Sample options matching the model config (patch size, radii, body query).
dataset::SampleOptions sample_options_for(const ModelConfig& model);
// FrameSelection for config.data: inputs t = first_frame .. (first_frame + max_frames - 2).
dataset::FrameSelection frame_selection_for(const DataConfig& data);

}  // namespace layersnet
