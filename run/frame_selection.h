#pragma once
// Which input frames of a sequence a config's [data] section uses. (The sample options of a
// model config, its patch size, radii and body query, come from model::sample_options_for.)
#include "dataset/sample.h"
#include "run/config.h"

namespace layersnet {

// FrameSelection for config.data: inputs t = first_frame .. (first_frame + max_frames - 2).
dataset::FrameSelection frame_selection_for(const DataConfig& data);

}  // namespace layersnet
