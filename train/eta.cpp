// Training ETA (see eta.h).
#include "train/eta.h"

#include <cmath>

namespace layersnet {

void TrainingEta::add_batch(double seconds, int64_t samples, int64_t self_fed_steps) {
  if (samples <= 0 || !(seconds >= 0)) return;
  const double s = static_cast<double>(samples), n = static_cast<double>(self_fed_steps);
  ss_ += s * s;
  sn_ += s * n;
  nn_ += n * n;
  ts_ += seconds * s;
  tn_ += seconds * n;
  ++batches_;
}

double TrainingEta::seconds_per_sample(double steps) const {
  if (batches_ == 0) return -1;
  const double det = ss_ * nn_ - sn_ * sn_;
  // The fit needs self-fed steps to lean on: with under half a step per sample so far (the first
  // two epochs of the official curriculum) its b is mostly noise and underestimated the rest of
  // a default run by a third; batches whose steps are proportional to their samples cannot
  // separate a from b at all.
  const double mean_steps = ss_ > 0 ? sn_ / ss_ : 0;
  if (mean_steps >= 0.5 && det > 1e-9 * ss_ * nn_) {
    const double a = (ts_ * nn_ - tn_ * sn_) / det, b = (ss_ * tn_ - sn_ * ts_) / det;
    if (a > 0 && b >= 0) return a + b * steps;
  }
  // One unknown: a self-fed step is a forward pass, a third of a recorded step's forward and
  // backward, so a sample with m mean steps costs a·(1 + m / 3).
  const double per_sample = ts_ / ss_;
  const double a = per_sample / (1 + mean_steps / 3);
  return a * (1 + steps / 3);
}

double TrainingEta::remaining_seconds(int64_t left_this_epoch, int max_steps_now, int64_t samples_per_epoch,
                                      const std::vector<int>& later_max_steps) const {
  if (batches_ == 0) return -1;
  double t = static_cast<double>(left_this_epoch) * seconds_per_sample(0.5 * max_steps_now);
  for (const int n : later_max_steps) t += static_cast<double>(samples_per_epoch) * seconds_per_sample(0.5 * n);
  return t;
}

}  // namespace layersnet
