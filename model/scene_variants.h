#pragma once
// The same scene with parts taken away, for measuring what each part of a scene costs
// (`layersnet bench scene`, tests/model/test_stage_times.cpp). Each variant keeps every
// remaining array bit-identical (same motion, same statistics), so a cost difference is the
// removed part's alone.
//
//   keep_first_garments  the inner `count` garments (vertices, faces, patches, adjacency);
//                        the outer ones vanish with their patches' world/inter edges.
//   move_body            the body translated by `offset` (scene units) in every frame: beyond
//                        R_b of every garment point there are no body neighbours, no nearest
//                        body vertices and hence no body tokens (ModelInput U = 0).
//   drop_wind            no wind: ModelInput has_wind = false (no wind token, no wind edges).
#include "autodiff/check.h"
#include "model/scene.h"

#include <algorithm>
#include <cstdint>
#include <vector>

namespace layersnet::model {

// Needs the scene's garments in order: garment g's vertices are garment_offsets[g..g+1),
// its patches a contiguous block after garment g-1's (patch_garment non-decreasing).
inline SceneWindow keep_first_garments(const SceneWindow& s, int count) {
  const int G = static_cast<int>(s.garment_offsets.size()) - 1;
  LAYERSNET_CHECK(count >= 1 && count <= G,
                  "keep_first_garments: count " << count << " must be in [1, " << G << "] (the scene's garments)");
  LAYERSNET_CHECK(std::is_sorted(s.patch_garment.begin(), s.patch_garment.end()),
                  "keep_first_garments: SceneWindow.patch_garment must be non-decreasing (patches grouped by garment)");
  SceneWindow o = s;
  const int32_t n = s.garment_offsets[count];
  const int32_t p = static_cast<int32_t>(
      std::lower_bound(s.patch_garment.begin(), s.patch_garment.end(), count) - s.patch_garment.begin());
  o.N = n, o.P = p;
  auto cut3 = [n](std::vector<double>& x) {
    if (!x.empty()) x.resize(3 * static_cast<std::size_t>(n));
  };
  cut3(o.x_tm2), cut3(o.x_tm1), cut3(o.x_t), cut3(o.x_tp1);
  o.faces.clear();
  for (std::size_t f = 0; f + 2 < s.faces.size(); f += 3) {
    const int32_t inside = (s.faces[f] < n) + (s.faces[f + 1] < n) + (s.faces[f + 2] < n);
    LAYERSNET_CHECK(inside == 0 || inside == 3, "keep_first_garments: face " << f / 3 << " joins two garments");
    if (inside == 3) o.faces.insert(o.faces.end(), s.faces.begin() + f, s.faces.begin() + f + 3);
  }
  o.garment_offsets.resize(count + 1);
  o.garment_attr.resize(5 * static_cast<std::size_t>(count));
  // CSR lists: keep the first rows; every kept item must point into the kept range.
  auto cut_csr = [](std::vector<int32_t>& offsets, std::vector<int32_t>& items, int32_t rows, int32_t limit,
                    const char* what) {
    offsets.resize(rows + 1);
    items.resize(offsets.back());
    for (int32_t x : items)
      LAYERSNET_CHECK(x < limit, "keep_first_garments: " << what << " links a kept garment to a removed one");
  };
  cut_csr(o.v2p_offsets, o.v2p_patches, n, p, "v2p");
  cut_csr(o.p2v_offsets, o.p2v_vertices, p, n, "p2v");
  cut_csr(o.adj_offsets, o.adj_patches, p, p, "mesh adjacency");
  o.own_patch.resize(n);
  o.patch_garment.resize(p);
  return o;
}

inline void move_body(SceneWindow& s, const double offset[3]) {
  for (auto* x : {&s.body_tm1, &s.body_t, &s.body_tp1})
    for (std::size_t i = 0; i < x->size(); ++i) (*x)[i] += offset[i % 3];
}

inline void drop_wind(SceneWindow& s) {
  s.has_wind = false;
  const double calm[5] = {1, 0, 0, 0, 0};
  std::copy(calm, calm + 5, s.wind_t), std::copy(calm, calm + 5, s.wind_tp1);
}

}  // namespace layersnet::model
