#pragma once
// Speed against accuracy (`layersnet bench trade`): the Pareto front of
// model variants over (ms per frame, error) and the three presets picked from it.
//
// Both coordinates are minimised. A point p is dominated when another point q is no worse
// in both (q.ms ≤ p.ms and q.error ≤ p.error) and strictly better in at least one. Points
// with the same (ms, error) do not dominate each other: all of them stay on the front.
// Points with a non-finite or non-positive ms, or a non-finite error (failed, skipped or
// diverged variants), are never on the front and never dominate.
#include <cstddef>
#include <string>
#include <vector>

namespace layersnet::eval {

struct TradePoint {
  std::string name;
  double ms = 0;     // ms per frame (rollout step, 1 thread)
  double error = 0;  // rollout error, mm
};

// True when `p` can be compared at all (finite error, finite ms > 0).
bool trade_point_valid(const TradePoint& p);

// Indices of the non-dominated points, sorted by ms ascending (ties: by error, then index).
std::vector<std::size_t> pareto_front(const std::vector<TradePoint>& points);

// The three presets, as indices into `points` (-1 when there is no valid point).
//   fast     = the front point with the lowest ms whose error ≤ (1 + tolerance) · the
//              reference's error (the reference: the default config); when the reference
//              is not valid, the fastest front point.
//   accurate = the front point with the lowest error (ties: the faster).
//   balanced = the knee between them: of the front points from fast to accurate (by ms),
//              the one farthest below the straight line fast–accurate in log(ms)–log(error)
//              axes (the most error saved per speed given up, relative to a straight trade).
//              When none lies below that line, the one with the lowest error · ms (equal
//              relative changes in speed and error weigh the same; ties: the lower error).
//              So ms(fast) ≤ ms(balanced) ≤ ms(accurate).
// Two presets can be the same point (e.g. a variant both fastest and most accurate).
struct PresetChoice {
  int fast = -1, balanced = -1, accurate = -1;
};
PresetChoice choose_presets(const std::vector<TradePoint>& points, int reference, double tolerance);

}  // namespace layersnet::eval
