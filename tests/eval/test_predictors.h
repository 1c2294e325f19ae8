#pragma once
// Sequences and predictors shared by the eval tests.
#include "dataset/synthetic.h"
#include "eval/rollout.h"

#include <limits>
#include <string>

namespace layersnet::eval::testing {

// A small synthetic sequence: `garments` tubes (4 rings x 8 segments) around a coarse body.
inline dataset::Sequence sequence(int garments, int frames = 10) {
  dataset::SyntheticOptions o;
  o.garments = garments;
  o.frames = frames;
  o.rings = 4;
  o.segments = 8;
  o.body_rings = 4;
  o.body_segments = 8;
  return dataset::make_synthetic_sequence(o);
}

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
