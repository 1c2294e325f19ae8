// The training ETA fits the cost of a sample and of a self-fed step and sums the curriculum ahead.
#include "train/eta.h"

#include <gtest/gtest.h>

namespace layersnet {
namespace {

TEST(TrainingEta, FitsTheCostOfASelfFedStepAndCountsTheLongerEpochsAhead) {
  // Ground truth: 0.2 s per sample plus 0.05 s per self-fed step.
  const auto cost = [](int64_t samples, int64_t steps) { return 0.2 * samples + 0.05 * steps; };
  TrainingEta eta;
  EXPECT_EQ(eta.remaining_seconds(10, 0, 100, {1, 2}), -1);
  eta.add_batch(cost(8, 0), 8, 0);  // epoch 1: no self-fed steps
  eta.add_batch(cost(8, 4), 8, 4);  // epoch 2: up to 1 step
  eta.add_batch(cost(8, 12), 8, 12);
  eta.add_batch(cost(8, 20), 8, 20);  // now 1.13 steps per sample: the fit takes over
  EXPECT_NEAR(eta.seconds_per_sample(0), 0.2, 1e-9);
  EXPECT_NEAR(eta.seconds_per_sample(4), 0.4, 1e-9);
  // 50 samples left at max 1 step (mean 0.5), then two epochs of 100 at max 3 and 9.
  const double expected = 50 * (0.2 + 0.05 * 0.5) + 100 * (0.2 + 0.05 * 1.5) + 100 * (0.2 + 0.05 * 4.5);
  EXPECT_NEAR(eta.remaining_seconds(50, 1, 100, {3, 9}), expected, 1e-9);
  // The rate of the last samples alone would say much less.
  EXPECT_GT(expected, 250 * 0.2 * 1.2);
}

TEST(TrainingEta, BeforeAnySelfFedStepAStepCostsAThirdOfASample) {
  TrainingEta eta;
  eta.add_batch(1.0, 10, 0);
  EXPECT_NEAR(eta.seconds_per_sample(0), 0.1, 1e-12);
  EXPECT_NEAR(eta.seconds_per_sample(3), 0.2, 1e-12);
  EXPECT_NEAR(eta.remaining_seconds(0, 0, 10, {2}), 10 * 0.1 * (1 + 1.0 / 3), 1e-12);
}

}  // namespace
}  // namespace layersnet
