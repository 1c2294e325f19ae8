#pragma once
// dataset::TrainingSample -> LossInput<float>: targets at t+1, GT patch centres and vertex
// normals, faces with global vertex ids, garment ranges, GT body positions and normals.
#include "dataset/sample.h"
#include "losses/losses.h"

namespace layersnet::losses {

LossInput<float> loss_input_from_sample(const dataset::TrainingSample& sample, const dataset::SequenceInfo& info);

}  // namespace layersnet::losses
