// The rollout's thread count chosen by timing (simulate/thread_choice.h): which count it tries
// when, what it keeps, and the premise that lets it choose freely, a rollout that gives the same
// positions at 1 and 2 threads.
#include "dataset/stats.h"
#include "dataset/synthetic.h"
#include "eval/rollout.h"
#include "simulate/simulate.h"
#include "simulate/thread_choice.h"
#include "tests/eval/cli_test_util.h"

#include <Eigen/Core>
#include <gtest/gtest.h>
#include <omp.h>

#include <filesystem>
#include <string>
#include <unistd.h>

namespace layersnet::eval {
namespace {

// Runs `steps` steps through the choice, each taking ms_at(threads, k).
template <class Time>
std::vector<int> drive(ThreadChoice& choice, int steps, Time ms_at) {
  std::vector<int> used;
  for (int k = 0; k < steps; ++k) {
    const int n = choice.threads_for_step(k);
    used.push_back(n);
    choice.record(k, ms_at(n, k));
  }
  return used;
}

TEST(ThreadChoice, TriesEachCountInTurnAndKeepsTheFaster) {
  ThreadChoice choice(4, 3, 10);
  // One thread is faster; step 0 (the caches) is slow whatever the count and not timed.
  const std::vector<int> used = drive(choice, 12, [](int n, int k) { return k == 0 ? 500.0 : (n == 1 ? 60.0 : 75.0); });
  const std::vector<int> expected = {4, 4, 1, 4, 1, 4, 1, 1, 1, 1, 1, 1};
  EXPECT_EQ(used, expected);
  EXPECT_EQ(choice.chosen(), 1);
  EXPECT_EQ(choice.choices_made(), 1);
  EXPECT_NE(choice.summary().find("1 of 4 threads by timing"), std::string::npos) << choice.summary();

  ThreadChoice more(2, 3, 10);
  drive(more, 12, [](int n, int) { return n == 2 ? 40.0 : 61.0; });
  EXPECT_EQ(more.chosen(), 2);
}

// One slow step (the machine busy for a moment) does not decide: the median of each count's steps does.
TEST(ThreadChoice, AnOutlierStepDoesNotDecide) {
  ThreadChoice choice(2, 3, 10);
  drive(choice, 8, [](int n, int k) { return n == 2 ? (k == 1 ? 900.0 : 40.0) : 60.0; });
  EXPECT_EQ(choice.chosen(), 2);
}

// After `hold` steps the counts are timed again, so a change of load is followed.
TEST(ThreadChoice, TimesAgainAfterTheHoldAndFollowsTheLoad) {
  ThreadChoice choice(2, 2, 5);
  // Steps 1-4 try, 5-9 hold, 10-13 try again, 14-18 hold: two threads pay until the machine gets
  // busy at step 8, then one thread does.
  const std::vector<int> used =
      drive(choice, 19, [](int n, int k) { return k < 8 ? (n == 2 ? 40.0 : 60.0) : (n == 2 ? 90.0 : 62.0); });
  const std::vector<int> expected = {2, 2, 1, 2, 1, 2, 2, 2, 2, 2, 2, 1, 2, 1, 1, 1, 1, 1, 1};
  EXPECT_EQ(used, expected);
  EXPECT_EQ(choice.chosen(), 1);
  EXPECT_EQ(choice.choices_made(), 2);
}

TEST(ThreadChoice, OneThreadIsNeverTimedAgainstItself) {
  ThreadChoice choice(1);
  const std::vector<int> used = drive(choice, 10, [](int, int) { return 50.0; });
  EXPECT_EQ(used, std::vector<int>(10, 1));
  EXPECT_EQ(choice.choices_made(), 0);
  EXPECT_EQ(choice.summary(), "1 thread");
  EXPECT_THROW(ThreadChoice(0), std::invalid_argument);
}

// The premise: a rollout's positions do not depend on the thread count, on a scene large enough
// that the model's row-split products, the nearest-vertex queries and the constraints do split
// (two tubes of 1,536 vertices each).
TEST(ThreadChoice, RolloutPositionsAreTheSameAtOneAndTwoThreads) {
  namespace fs = std::filesystem;
  const fs::path root = fs::temp_directory_path() / ("layersnet_thread_choice_" + std::to_string(::getpid()));
  fs::remove_all(root);
  dataset::SyntheticOptions o;
  o.garments = 2;
  o.frames = 8;
  o.rings = 32;
  o.segments = 48;
  o.body_rings = 24;
  o.body_segments = 32;
  o.height = 17.f;
  const auto m = dataset::write_synthetic_dataset((root / "data").string(), 1, 0, 0, o);
  const auto stats = dataset::compute_stats(m);
  // The inertial base keeps the output layer random (with the other bases it starts at zero), so the
  // network's products reach the positions.
  cli_test::write_tiny_checkpoint(root / "tiny.h5", stats, "", {"eval.constraints=true", "model.velocity_base=inertia"});
  const dataset::Sequence seq = dataset::read_sequence(m.sequence_path(m.train.front()));
  ASSERT_GE(seq.info.num_garments(), 2);
  Eigen::setNbThreads(1);  // as simulate
  const int before = omp_get_max_threads();
  std::vector<Rollout> runs;
  for (int threads : {1, 2}) {
    omp_set_num_threads(threads);
    auto model = load_model_predictor((root / "tiny.h5").string(), "tiny", nullptr);
    runs.push_back(rollout(*model, seq, 2, seq.info.num_frames - 3));
  }
  omp_set_num_threads(before);
  ASSERT_EQ(runs[0].frames.size(), runs[1].frames.size());
  ASSERT_FALSE(runs[0].frames.empty());
  for (size_t k = 0; k < runs[0].frames.size(); ++k) EXPECT_EQ(runs[0].frames[k], runs[1].frames[k]) << "frame " << k;
  fs::remove_all(root);
}

}  // namespace
}  // namespace layersnet::eval
