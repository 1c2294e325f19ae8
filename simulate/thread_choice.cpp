#include "simulate/thread_choice.h"

#include <algorithm>
#include <cstdio>
#include <stdexcept>

namespace layersnet::eval {
namespace {

double median_of(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  const size_t n = v.size();
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

}  // namespace

ThreadChoice::ThreadChoice(int max_threads, int trials, int hold) : trials_(trials), hold_(hold), chosen_(max_threads) {
  if (max_threads < 1 || trials < 1 || hold < 0)
    throw std::invalid_argument("ThreadChoice: needs max_threads >= 1, trials >= 1 and hold >= 0");
  candidates_.push_back(max_threads);
  if (max_threads > 1) candidates_.push_back(1);
  times_.resize(candidates_.size());
}

int ThreadChoice::threads_for_step(int k) {
  if (candidates_.size() < 2 || k < phase_start_) return chosen_;
  const int i = k - phase_start_;
  if (i < trial_steps()) return candidates_[static_cast<size_t>(i) % candidates_.size()];
  return chosen_;
}

void ThreadChoice::record(int k, double ms) {
  if (candidates_.size() < 2 || k < phase_start_) return;
  const int i = k - phase_start_;
  if (i < trial_steps()) {
    times_[static_cast<size_t>(i) % candidates_.size()].push_back(ms);
    if (i + 1 == trial_steps()) choose();
  } else if (i + 1 >= trial_steps() + hold_) {
    phase_start_ = k + 1;  // trials again from the next step
  }
}

void ThreadChoice::choose() {
  last_medians_.clear();
  size_t best = 0;
  for (size_t c = 0; c < candidates_.size(); ++c) {
    last_medians_.push_back(median_of(times_[c]));
    if (last_medians_[c] < last_medians_[best]) best = c;
    times_[c].clear();
  }
  chosen_ = candidates_[best];
  ++choices_;
}

std::string ThreadChoice::summary() const {
  char buf[200];
  if (candidates_.size() < 2 || choices_ == 0) {
    std::snprintf(buf, sizeof buf, "%d thread%s", chosen_, chosen_ == 1 ? "" : "s");
    return buf;
  }
  std::snprintf(buf, sizeof buf, "%d of %d threads by timing (last medians %.1f ms at %d, %.1f ms at %d, over %d steps each; chosen %d time%s)",
                chosen_, candidates_.front(), last_medians_[0], candidates_[0], last_medians_[1], candidates_[1], trials_,
                choices_, choices_ == 1 ? "" : "s");
  return buf;
}

}  // namespace layersnet::eval
