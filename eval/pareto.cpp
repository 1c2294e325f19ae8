#include "eval/pareto.h"

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
  std::size_t bal = front.front();
  for (std::size_t i : front) {
    const double v = points[i].error * points[i].ms, best = points[bal].error * points[bal].ms;
    if (v < best || (v == best && points[i].error < points[bal].error)) bal = i;
  }
  c.balanced = static_cast<int>(bal);
  return c;
}

}  // namespace layersnet::eval
