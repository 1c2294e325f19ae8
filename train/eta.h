#pragma once
// The time a training run has left. A sample with n self-fed steps costs about a + b·n seconds
// (one recorded step plus n forward passes), and the curriculum raises n epoch by epoch, so
// the rate of the last samples underestimates the rest. The estimator fits a and b by least
// squares over every batch seen (seconds, samples, self-fed steps) and sums the remaining
// epochs at their expected steps: a sample of an epoch whose curriculum allows up to N draws
// n uniformly from 0..N, so n averages N / 2.
#include <cstdint>
#include <vector>

namespace layersnet {

class TrainingEta {
 public:
  // One batch: its wall seconds, samples and total self-fed steps over its samples.
  void add_batch(double seconds, int64_t samples, int64_t self_fed_steps);
  // Seconds per sample with n self-fed steps: a + b·n, fitted once the batches seen average
  // at least half a self-fed step per sample; before that a step is taken to cost a third of
  // a sample's base (b = a / 3: a forward pass against a forward and a backward).
  double seconds_per_sample(double self_fed_steps) const;
  // Seconds left: `left_this_epoch` samples of the current epoch (curriculum maximum
  // max_steps_now), then samples_per_epoch for each later epoch's maximum in later_max_steps.
  // -1 before any batch.
  double remaining_seconds(int64_t left_this_epoch, int max_steps_now, int64_t samples_per_epoch,
                           const std::vector<int>& later_max_steps) const;

 private:
  // Sums of the normal equations of seconds ≈ a·samples + b·steps over batches.
  double ss_ = 0, sn_ = 0, nn_ = 0, ts_ = 0, tn_ = 0;
  int64_t batches_ = 0;
};

}  // namespace layersnet
