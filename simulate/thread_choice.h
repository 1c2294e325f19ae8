#pragma once
// The rollout's OpenMP thread count, chosen by timing the steps themselves. A rollout step gives
// the same positions at any thread count (its kernels split work by rows, never by threads), so
// only its time depends on the count, and which count is faster depends on the machine, the
// scene's size and what else runs beside it (docs/decisions.md, "Threads chosen by timing in
// simulate").
//
// From step 1 on (step 0 also builds the caches every later step reuses, so it is not timed), each
// candidate runs `trials` steps in turn; the one with the lower median time is then kept for
// `hold` steps, after which the trials run again, so that a change of load is followed.
#include <string>
#include <vector>

namespace layersnet::eval {

class ThreadChoice {
 public:
  // max_threads: the most threads to use (the other candidate is 1; with 1, nothing is tried).
  explicit ThreadChoice(int max_threads, int trials = 3, int hold = 100);

  // The thread count for step k (0-based, called in order of k).
  int threads_for_step(int k);
  // Step k, run at threads_for_step(k), took `ms` milliseconds.
  void record(int k, double ms);

  int chosen() const { return chosen_; }   // the count held now (max_threads until a choice is made)
  int choices_made() const { return choices_; }
  // "1 of 2 threads by timing (last medians 70.4 ms at 2, 61.2 ms at 1, over 3 steps each; chosen 2
  // times)", or "2 threads" when nothing was timed.
  std::string summary() const;

 private:
  int trial_steps() const { return trials_ * static_cast<int>(candidates_.size()); }
  void choose();

  std::vector<int> candidates_;  // thread counts tried, largest first
  int trials_, hold_;
  int chosen_;
  int phase_start_ = 1;          // first step of the current trial phase
  int choices_ = 0;
  std::vector<std::vector<double>> times_;  // per candidate, this phase's step times (ms)
  std::vector<double> last_medians_;
};

}  // namespace layersnet::eval
