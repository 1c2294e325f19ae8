#pragma once
// Patches from UV (paper eq. 2; official `patchwise` in
// datasets/utils/mesh.py).
//
// For each panel (UV island, in ascending panel id):
//   1. each face goes to the grid cell floor(c / patch_size) of its UV centroid c;
//   2. every vertex of the face joins that cell's patch (a vertex on a cell border or a
//      seam belongs to several patches; (vertex, patch) pairs are unique);
//   3. cells are numbered densely in lexicographic (u-cell, v-cell) order — the order of
//      the official id cell_u*max_col + cell_v — and offset by the patches of earlier panels.
// A vertex's own patch is the lowest patch id containing it (official argmax of g2p).
// Patch adjacency: for every mesh edge (u, v) all pairs P(u) x P(v), both directions,
// self-pairs included (so every patch is adjacent to itself).
// A vertex in no face belongs to no patch; its own patch is -1.
//
// Static per garment: build once and cache (training samples reuse it).
#include "dataset/sequence.h"

#include <Eigen/Core>

#include <cstdint>
#include <vector>

namespace layersnet::dataset {

inline constexpr float kDefaultPatchSize = 0.04f;  // UV units (official 0.04)

// Compressed rows: the entries of row i are items[offsets[i] .. offsets[i+1]).
struct Csr {
  std::vector<int32_t> offsets{0};  // (rows + 1)
  std::vector<int32_t> items;
  int rows() const { return static_cast<int>(offsets.size()) - 1; }
  int size(int i) const { return offsets[i + 1] - offsets[i]; }
  const int32_t* begin(int i) const { return items.data() + offsets[i]; }
  const int32_t* end(int i) const { return items.data() + offsets[i + 1]; }
};

struct PatchStructure {
  int num_vertices = 0;             // N
  int num_patches = 0;              // P
  Csr vertex_patches;               // N rows: patches of each vertex, ascending
  Csr patch_vertices;               // P rows: member vertices of each patch, ascending
  std::vector<int32_t> own_patch;   // (N,) lowest patch of each vertex, -1 if none
  std::vector<int32_t> patch_panel; // (P,) panel id of each patch
  Csr adjacency;                    // P rows: mesh-adjacent patches (self included), ascending
};

PatchStructure build_patches(const GarmentMesh& garment, float patch_size = kDefaultPatchSize);

// Mean of member-vertex rows per patch: x (N, C) -> (P, C). A patch always has members.
template <typename Derived>
Eigen::Matrix<float, Eigen::Dynamic, Derived::ColsAtCompileTime,
              Derived::ColsAtCompileTime == 1 ? Eigen::ColMajor : Eigen::RowMajor>
patch_means(const PatchStructure& s, const Eigen::MatrixBase<Derived>& x) {
  Eigen::Matrix<float, Eigen::Dynamic, Derived::ColsAtCompileTime,
                Derived::ColsAtCompileTime == 1 ? Eigen::ColMajor : Eigen::RowMajor>
      out(s.num_patches, x.cols());
  for (int p = 0; p < s.num_patches; ++p) {
    out.row(p).setZero();
    for (const int32_t* v = s.patch_vertices.begin(p); v != s.patch_vertices.end(p); ++v)
      out.row(p) += x.row(*v);
    out.row(p) /= static_cast<float>(std::max(s.patch_vertices.size(p), 1));
  }
  return out;
}

// Several garments as one patch set: garment g's vertices are offset by the vertices of
// garments 0..g-1 and its patches by their patches (the official cross-garment order).
// Adjacency stays within a garment. vertex_offsets/patch_offsets get G+1 entries.
PatchStructure concat_patches(const std::vector<const PatchStructure*>& garments,
                              std::vector<int32_t>* vertex_offsets = nullptr,
                              std::vector<int32_t>* patch_offsets = nullptr);

// Unique undirected mesh edges (u < v) of a triangle mesh: (E, 2).
std::vector<std::pair<int32_t, int32_t>> mesh_edges(const Faces& faces);

}  // namespace layersnet::dataset
