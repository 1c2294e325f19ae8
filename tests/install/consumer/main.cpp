// A program outside LayersNet that runs a packed model through the installed libraries: it rolls
// the model over a small synthetic two-garment scene and fails on a non-finite or runaway frame.
#include "dataset/synthetic.h"
#include "eval/rollout.h"

#include <cmath>
#include <cstdio>
#include <exception>

int main(int argc, char** argv) {
  namespace ln = layersnet;
  if (argc != 2) {
    std::fprintf(stderr, "usage: %s MODEL.h5\n", argv[0]);
    return 2;
  }
  try {
    ln::dataset::SyntheticOptions options;
    options.frames = 8;
    options.garments = 2;
    const ln::dataset::Sequence seq = ln::dataset::make_synthetic_sequence(options);
    const auto model = ln::eval::load_model_predictor(argv[1], "model", nullptr);
    const ln::eval::Rollout r = ln::eval::rollout(*model, seq, 2, 5);
    if (r.diverged_at >= 0) {
      std::fprintf(stderr, "consumer: the rollout left the finite numbers at frame %d\n", r.first_frame + r.diverged_at);
      return 1;
    }
    double distance = 0;  // mean over frames and vertices, scene units
    for (std::size_t k = 0; k < r.frames.size(); ++k)
      distance += (r.frames[k] - ln::eval::garments_at(seq, r.first_frame + static_cast<int>(k))).rowwise().norm().mean();
    distance /= static_cast<double>(r.frames.size());
    std::printf("consumer: %zu frames of %ld garment vertices, mean distance to the scripted motion %.3f units\n",
                r.frames.size(), static_cast<long>(r.frames.front().rows()), distance);
    // The synthetic tubes only translate by 0.3 units; a model that ran at all stays near them.
    return std::isfinite(distance) && distance < 2.0 ? 0 : 1;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "consumer: %s\n", e.what());
    return 1;
  }
}
