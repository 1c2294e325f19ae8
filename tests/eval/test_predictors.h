#pragma once
// Predictors shared by the eval tests.
#include "eval/rollout.h"

#include <limits>
#include <string>

namespace layersnet::eval::testing {

// Predicts the ground truth, then NaN from rollout frame 1 on.
struct Diverging : Predictor {
  int calls = 0;
  std::string name() const override { return "diverging"; }
  Points step(const dataset::Sequence& seq, int t, const Points&, const Points&, const Points&) override {
    Points x = garments_at(seq, t + 1);
    if (calls++ >= 1) x(0, 0) = std::numeric_limits<float>::quiet_NaN();
    return x;
  }
};

}  // namespace layersnet::eval::testing
