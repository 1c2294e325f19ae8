// Patch construction from face-UV centroids (see patches.h for the rules).
#include "dataset/patches.h"

#include <algorithm>
#include <cmath>
#include <map>

namespace layersnet::dataset {
namespace {

// Builds CSR from (row, item) pairs; rows sorted, items unique and ascending.
Csr to_csr(std::vector<std::pair<int32_t, int32_t>> pairs, int rows) {
  std::sort(pairs.begin(), pairs.end());
  pairs.erase(std::unique(pairs.begin(), pairs.end()), pairs.end());
  Csr c;
  c.offsets.assign(static_cast<size_t>(rows) + 1, 0);
  c.items.reserve(pairs.size());
  for (const auto& [r, i] : pairs) {
    ++c.offsets[static_cast<size_t>(r) + 1];
    c.items.push_back(i);
  }
  for (int r = 0; r < rows; ++r) c.offsets[r + 1] += c.offsets[r];
  return c;
}

// floor(x) as an integer cell, clamped so that absurd (but finite) UVs stay defined.
int64_t cell_of(float x) {
  const double c = std::floor(static_cast<double>(x));
  return static_cast<int64_t>(std::clamp(c, -1e15, 1e15));
}

}  // namespace

std::vector<std::pair<int32_t, int32_t>> mesh_edges(const Faces& faces) {
  std::vector<std::pair<int32_t, int32_t>> e;
  e.reserve(static_cast<size_t>(faces.rows()) * 3);
  for (Eigen::Index f = 0; f < faces.rows(); ++f)
    for (int k = 0; k < 3; ++k) {
      const int32_t a = faces(f, k), b = faces(f, (k + 1) % 3);
      if (a != b) e.emplace_back(std::min(a, b), std::max(a, b));
    }
  std::sort(e.begin(), e.end());
  e.erase(std::unique(e.begin(), e.end()), e.end());
  return e;
}

PatchStructure build_patches(const GarmentMesh& g, float patch_size) {
  PatchStructure s;
  s.num_vertices = g.num_vertices;
  const int F = g.num_faces();
  // Cell of every face: (panel, cell_u, cell_v); dense ids follow the sorted order of these
  // keys, i.e. panels ascending, then the official lexicographic cell order within a panel.
  using Key = std::tuple<int32_t, int64_t, int64_t>;
  std::vector<Key> face_key(F);
  for (int f = 0; f < F; ++f) {
    const float cu = (g.uv(3 * f, 0) + g.uv(3 * f + 1, 0) + g.uv(3 * f + 2, 0)) / 3.f;
    const float cv = (g.uv(3 * f, 1) + g.uv(3 * f + 1, 1) + g.uv(3 * f + 2, 1)) / 3.f;
    face_key[f] = {g.panel[f], cell_of(cu / patch_size), cell_of(cv / patch_size)};
  }
  std::map<Key, int32_t> ids;
  for (const Key& k : face_key) ids.emplace(k, 0);
  for (auto& [key, id] : ids) {
    id = s.num_patches++;
    s.patch_panel.push_back(std::get<0>(key));
  }
  std::vector<std::pair<int32_t, int32_t>> vp;  // (vertex, patch)
  vp.reserve(static_cast<size_t>(F) * 3);
  for (int f = 0; f < F; ++f) {
    const int32_t p = ids[face_key[f]];
    for (int k = 0; k < 3; ++k) vp.emplace_back(g.faces(f, k), p);
  }
  s.vertex_patches = to_csr(vp, s.num_vertices);
  std::vector<std::pair<int32_t, int32_t>> pv;
  pv.reserve(s.vertex_patches.items.size());
  s.own_patch.assign(s.num_vertices, -1);
  for (int v = 0; v < s.num_vertices; ++v) {
    if (s.vertex_patches.size(v) > 0) s.own_patch[v] = *s.vertex_patches.begin(v);
    for (const int32_t* p = s.vertex_patches.begin(v); p != s.vertex_patches.end(v); ++p) pv.emplace_back(*p, v);
  }
  s.patch_vertices = to_csr(pv, s.num_patches);
  std::vector<std::pair<int32_t, int32_t>> adj;
  for (const auto& [u, v] : mesh_edges(g.faces))
    for (const int32_t* a = s.vertex_patches.begin(u); a != s.vertex_patches.end(u); ++a)
      for (const int32_t* b = s.vertex_patches.begin(v); b != s.vertex_patches.end(v); ++b) {
        adj.emplace_back(*a, *b);
        adj.emplace_back(*b, *a);
      }
  for (int p = 0; p < s.num_patches; ++p) adj.emplace_back(p, p);
  s.adjacency = to_csr(adj, s.num_patches);
  return s;
}

PatchStructure concat_patches(const std::vector<const PatchStructure*>& garments, std::vector<int32_t>* vertex_offsets,
                              std::vector<int32_t>* patch_offsets) {
  PatchStructure out;
  std::vector<int32_t> vo{0}, po{0};
  auto append = [](Csr& dst, const Csr& src, int32_t item_offset) {
    const int32_t base = dst.offsets.back();
    for (size_t r = 1; r < src.offsets.size(); ++r) dst.offsets.push_back(base + src.offsets[r]);
    for (int32_t x : src.items) dst.items.push_back(x + item_offset);
  };
  for (const PatchStructure* g : garments) {
    append(out.vertex_patches, g->vertex_patches, out.num_patches);
    append(out.patch_vertices, g->patch_vertices, out.num_vertices);
    append(out.adjacency, g->adjacency, out.num_patches);
    for (int32_t p : g->own_patch) out.own_patch.push_back(p < 0 ? -1 : p + out.num_patches);
    out.patch_panel.insert(out.patch_panel.end(), g->patch_panel.begin(), g->patch_panel.end());
    out.num_vertices += g->num_vertices;
    out.num_patches += g->num_patches;
    vo.push_back(out.num_vertices);
    po.push_back(out.num_patches);
  }
  if (vertex_offsets) *vertex_offsets = vo;
  if (patch_offsets) *patch_offsets = po;
  return out;
}

}  // namespace layersnet::dataset
