#include "eval/tether.h"

#include "eval/rollout.h"

#include <algorithm>
#include <functional>
#include <utility>

namespace layersnet::eval {
namespace {

// Member sums and counts per patch: the centre of a vertex's patch mates in O(1), kept
// current as vertices move.
struct PatchSums {
  PatchSums(const dataset::PatchStructure& s, const dataset::Points& x)
      : s(s), sum(dataset::Points::Zero(s.num_patches, 3)), count(s.num_patches) {
    for (int p = 0; p < s.num_patches; ++p) {
      count[p] = s.patch_vertices.size(p);
      for (const int32_t* v = s.patch_vertices.begin(p); v != s.patch_vertices.end(p); ++v) sum.row(p) += x.row(*v);
    }
  }
  // Mean of the other members of v's own patch (v at x_v); false without own patch or mates.
  bool mates_centre(int v, const Eigen::RowVector3f& x_v, Eigen::RowVector3f& centre) const {
    const int p = s.own_patch[v];
    if (p < 0 || count[p] < 2) return false;
    centre = (sum.row(p) - x_v) / static_cast<float>(count[p] - 1);
    return true;
  }
  void move(int v, const Eigen::RowVector3f& by) {
    for (const int32_t* p = s.vertex_patches.begin(v); p != s.vertex_patches.end(v); ++p) sum.row(*p) += by;
  }
  const dataset::PatchStructure& s;
  dataset::Points sum;
  std::vector<int> count;
};

// Per vertex (N,): distance from its patch mates' centre (0 without mates).
std::vector<double> mates_distances(const dataset::PatchStructure& s, const dataset::Points& x) {
  const PatchSums sums(s, x);
  std::vector<double> distance(s.num_vertices, 0.0);
  Eigen::RowVector3f centre;
  for (int v = 0; v < s.num_vertices; ++v)
    if (sums.mates_centre(v, x.row(v), centre)) distance[v] = (x.row(v) - centre).norm();
  return distance;
}

// (P,) ρ_p: the largest rest distance of a member from its mates' centre, at least the median
// over patches (a patch of two close vertices has a tiny radius that folding cloth exceeds).
std::vector<double> patch_radii(const dataset::PatchStructure& s, const dataset::Points& rest) {
  const std::vector<double> distance = mates_distances(s, rest);
  std::vector<double> radius(s.num_patches, 0.0);
  for (int v = 0; v < s.num_vertices; ++v)
    if (s.own_patch[v] >= 0) radius[s.own_patch[v]] = std::max(radius[s.own_patch[v]], distance[v]);
  if (radius.empty()) return radius;
  std::vector<double> sorted = radius;
  std::nth_element(sorted.begin(), sorted.begin() + sorted.size() / 2, sorted.end());
  const double median = sorted[sorted.size() / 2];
  for (double& r : radius) r = std::max(r, median);
  return radius;
}

// One pass of apply_tether; returns how many vertices it moved.
int tether_pass(const dataset::PatchStructure& s, const std::vector<float>& limit, dataset::Points& x) {
  PatchSums sums(s, x);
  // Worst first, one at a time, the sums kept current: a runaway vertex is moved before its
  // patch mates are looked at, so its pull on their centres is gone by then.
  std::vector<std::pair<double, int>> beyond;
  Eigen::RowVector3f centre;
  for (int v = 0; v < s.num_vertices; ++v)
    if (limit[v] > 0.f && sums.mates_centre(v, x.row(v), centre)) {
      const double ratio = (x.row(v) - centre).norm() / double(limit[v]);
      if (ratio > 1.0) beyond.push_back({ratio, v});  // NaN compares false: stays visible
    }
  std::sort(beyond.begin(), beyond.end(), std::greater<>());
  int moved = 0;
  for (const auto& [ratio, v] : beyond) {
    sums.mates_centre(v, x.row(v), centre);
    const Eigen::RowVector3f offset = x.row(v) - centre;
    const float length = offset.norm();
    if (!(length > limit[v])) continue;  // its mates have moved since
    const Eigen::RowVector3f to = centre + offset * (limit[v] / length);
    sums.move(v, to - x.row(v));
    x.row(v) = to;
    ++moved;
  }
  return moved;
}

}  // namespace

std::vector<float> tether_limits(const dataset::Sequence& seq, const dataset::SequenceStructure& structure,
                                 double factor) {
  const dataset::PatchStructure& s = structure.all;
  const std::vector<double> radius = patch_radii(s, rest_garments(seq));
  std::vector<float> limit(s.num_vertices, 0.f);
  for (int v = 0; v < s.num_vertices; ++v)
    if (s.own_patch[v] >= 0) limit[v] = static_cast<float>(factor * radius[s.own_patch[v]]);
  return limit;
}

int apply_tether(const dataset::PatchStructure& s, const std::vector<float>& limit, dataset::Points& x) {
  // A move shifts its mates' centres a little, so a pass can leave a vertex just beyond;
  // passes repeat until none moves (the first does nearly all the work).
  constexpr int kMaxPasses = 8;
  int moved = 0;
  for (int pass = 0; pass < kMaxPasses; ++pass) {
    const int n = tether_pass(s, limit, x);
    moved += n;
    if (n == 0) break;
  }
  return moved;
}

double tether_ratio(const dataset::PatchStructure& s, const std::vector<float>& limit, const dataset::Points& x) {
  const std::vector<double> distance = mates_distances(s, x);
  double worst = 0;
  for (int v = 0; v < s.num_vertices; ++v)
    if (limit[v] > 0.f) worst = std::max(worst, distance[v] / limit[v]);
  return worst;
}

double data_tether_ratio(const dataset::Sequence& seq, const dataset::SequenceStructure& structure, int first) {
  const std::vector<float> radius = tether_limits(seq, structure, 1.0);
  double worst = 0;
  for (int t = std::max(first, 0); t < seq.info.num_frames; ++t)
    worst = std::max(worst, tether_ratio(structure.all, radius, garments_at(seq, t)));
  return worst;
}

}  // namespace layersnet::eval
