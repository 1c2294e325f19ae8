#include "bench/pareto.h"

#include <algorithm>
#include <cmath>

namespace layersnet::eval {

bool trade_point_valid(const TradePoint& p) {
  return std::isfinite(p.ms) && p.ms > 0 && std::isfinite(p.error);
}

std::vector<std::size_t> pareto_front(const std::vector<TradePoint>& points) {
  std::vector<std::size_t> front;
  for (std::size_t i = 0; i < points.size(); ++i) {
    if (!trade_point_valid(points[i])) continue;
    bool dominated = false;
    for (std::size_t j = 0; j < points.size() && !dominated; ++j) {
      if (j == i || !trade_point_valid(points[j])) continue;
      const TradePoint &p = points[i], &q = points[j];
      dominated = q.ms <= p.ms && q.error <= p.error && (q.ms < p.ms || q.error < p.error);
    }
    if (!dominated) front.push_back(i);
  }
  std::sort(front.begin(), front.end(), [&](std::size_t a, std::size_t b) {
    if (points[a].ms != points[b].ms) return points[a].ms < points[b].ms;
    if (points[a].error != points[b].error) return points[a].error < points[b].error;
    return a < b;
  });
  return front;
}

PresetChoice choose_presets(const std::vector<TradePoint>& points, int reference, double tolerance) {
  PresetChoice c;
  const std::vector<std::size_t> front = pareto_front(points);
  if (front.empty()) return c;
  const bool has_ref = reference >= 0 && reference < static_cast<int>(points.size()) &&
                       trade_point_valid(points[static_cast<std::size_t>(reference)]);
  const double limit = has_ref ? (1 + tolerance) * points[static_cast<std::size_t>(reference)].error : INFINITY;
  // The front is sorted by ms, so the first point under the limit is the fastest one.
  for (std::size_t i : front)
    if (points[i].error <= limit) {
      c.fast = static_cast<int>(i);
      break;
    }
  if (c.fast < 0) c.fast = static_cast<int>(front.front());
  // Along the front, error falls as ms rises: the lowest error is the last point (ties in
  // error cannot both be on the front unless ms ties too, and then the first is kept).
  std::size_t acc = front.front();
  for (std::size_t i : front)
    if (points[i].error < points[acc].error) acc = i;
  c.accurate = static_cast<int>(acc);
  // Balanced: among the front points from fast to accurate (the front is sorted by ms, so
  // they are a contiguous run), the one farthest below the chord fast–accurate in
  // log(ms)–log(error) axes: the knee.
  const auto pos = [&](std::size_t i) { return std::find(front.begin(), front.end(), i) - front.begin(); };
  const auto a = pos(static_cast<std::size_t>(c.fast)), b = pos(acc);
  const auto lo = std::min(a, b), hi = std::max(a, b);
  const double x0 = std::log(points[front[lo]].ms), y0 = std::log(points[front[lo]].error);
  const double x1 = std::log(points[front[hi]].ms), y1 = std::log(points[front[hi]].error);
  std::size_t bal = front[lo];
  double best_below = 0;
  for (auto k = lo + 1; k < hi; ++k) {
    const TradePoint& q = points[front[k]];
    if (!(q.error > 0) || x1 <= x0) break;
    const double t = (std::log(q.ms) - x0) / (x1 - x0);
    const double below = (y0 + t * (y1 - y0)) - std::log(q.error);  // vertical gap under the chord
    if (below > best_below) best_below = below, bal = front[k];
  }
  if (best_below <= 0) {  // no knee (straight or bulging front): the lowest error × ms in the run
    for (auto k = lo; k <= hi; ++k) {
      const std::size_t i = front[k];
      const double v = points[i].error * points[i].ms, best = points[bal].error * points[bal].ms;
      if (v < best || (v == best && points[i].error < points[bal].error)) bal = i;
    }
  }
  c.balanced = static_cast<int>(bal);
  return c;
}

}  // namespace layersnet::eval
