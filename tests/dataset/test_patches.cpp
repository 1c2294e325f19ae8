// Patches from UV on meshes whose patches can be counted by hand.
#include "dataset/patches.h"
#include "dataset/synthetic.h"

#include <gtest/gtest.h>

namespace layersnet::dataset {
namespace {

// A flat grid of cols x rows unit squares (each split into 2 triangles), UV = position * cell,
// vertex (i, j) has index j*(cols+1)+i. Every face on panel `panel`.
GarmentMesh grid(int cols, int rows, float cell, int panel = 0) {
  GarmentMesh g;
  g.name = "grid";
  g.type = "test";
  g.num_vertices = (cols + 1) * (rows + 1);
  std::vector<int32_t> f;
  std::vector<float> uv;
  auto vid = [&](int i, int j) { return j * (cols + 1) + i; };
  auto corner = [&](int i, int j) { uv.push_back(i * cell); uv.push_back(j * cell); };
  for (int j = 0; j < rows; ++j)
    for (int i = 0; i < cols; ++i) {
      f.insert(f.end(), {vid(i, j), vid(i + 1, j), vid(i, j + 1)});
      corner(i, j), corner(i + 1, j), corner(i, j + 1);
      f.insert(f.end(), {vid(i + 1, j), vid(i + 1, j + 1), vid(i, j + 1)});
      corner(i + 1, j), corner(i + 1, j + 1), corner(i, j + 1);
    }
  g.faces = Eigen::Map<Faces>(f.data(), static_cast<Eigen::Index>(f.size() / 3), 3);
  g.uv = Eigen::Map<Uvs>(uv.data(), static_cast<Eigen::Index>(uv.size() / 2), 2);
  g.panel.assign(f.size() / 3, panel);
  return g;
}

std::vector<int32_t> row(const Csr& c, int i) { return {c.begin(i), c.end(i)}; }

TEST(Patches, TwoSquaresOfPatchSizeGiveTwoPatches) {
  // 2 x 1 squares of 0.04: one patch per square; the middle column (vertices 1 and 4)
  // belongs to both.
  const PatchStructure s = build_patches(grid(2, 1, 0.04f), 0.04f);
  ASSERT_EQ(s.num_patches, 2);
  EXPECT_EQ(row(s.patch_vertices, 0), (std::vector<int32_t>{0, 1, 3, 4}));
  EXPECT_EQ(row(s.patch_vertices, 1), (std::vector<int32_t>{1, 2, 4, 5}));
  EXPECT_EQ(row(s.vertex_patches, 1), (std::vector<int32_t>{0, 1}));
  EXPECT_EQ(row(s.vertex_patches, 2), (std::vector<int32_t>{1}));
  EXPECT_EQ(s.own_patch, (std::vector<int32_t>{0, 0, 1, 0, 0, 1}));
  EXPECT_EQ(row(s.adjacency, 0), (std::vector<int32_t>{0, 1}));
  EXPECT_EQ(row(s.adjacency, 1), (std::vector<int32_t>{0, 1}));
}

TEST(Patches, FourByFourSmallSquaresGiveFourPatchesOfNineVertices) {
  // 4 x 4 squares of 0.02 with patch size 0.04: 2 x 2 patches, each a 3 x 3 block of vertices.
  const PatchStructure s = build_patches(grid(4, 4, 0.02f), 0.04f);
  ASSERT_EQ(s.num_patches, 4);
  for (int p = 0; p < 4; ++p) EXPECT_EQ(s.patch_vertices.size(p), 9);
  // Official order: id = cell_u * max_col + cell_v, so patch 1 is cell (u 0, v 1).
  EXPECT_EQ(row(s.patch_vertices, 1), (std::vector<int32_t>{10, 11, 12, 15, 16, 17, 20, 21, 22}));
  // The centre vertex (2, 2) = 12 is in all four patches; its own patch is 0.
  EXPECT_EQ(row(s.vertex_patches, 12), (std::vector<int32_t>{0, 1, 2, 3}));
  EXPECT_EQ(s.own_patch[12], 0);
  EXPECT_EQ(s.own_patch[24], 3);
  // With 0.08 the whole grid is one patch; with 0.02, one patch per square (16).
  EXPECT_EQ(build_patches(grid(4, 4, 0.02f), 0.08f).num_patches, 1);
  EXPECT_EQ(build_patches(grid(4, 4, 0.02f), 0.02f).num_patches, 16);
}

TEST(Patches, AdjacencyFollowsMeshEdgesIncludingTheOfficialTwoStepPairs) {
  // 3 x 1 squares: patches 0, 1, 2. Edge (1, 2) lies in square 1 and its end points are in
  // patches {0, 1} and {1, 2}, so the official rule P(u) x P(v) makes 0 and 2 adjacent too.
  const PatchStructure s = build_patches(grid(3, 1, 0.04f), 0.04f);
  ASSERT_EQ(s.num_patches, 3);
  EXPECT_EQ(row(s.adjacency, 0), (std::vector<int32_t>{0, 1, 2}));
  // 5 x 1: patches 0 and 4 share no edge-connected vertex sets: not adjacent.
  const PatchStructure l = build_patches(grid(5, 1, 0.04f), 0.04f);
  EXPECT_EQ(row(l.adjacency, 0), (std::vector<int32_t>{0, 1, 2}));
  EXPECT_EQ(row(l.adjacency, 4), (std::vector<int32_t>{2, 3, 4}));
}

TEST(Patches, PanelsAreNumberedInPanelOrderEvenWhenTheirUvsOverlap) {
  // Two disjoint 2 x 1 strips on panels 7 and 3, laid on the same UV region.
  GarmentMesh a = grid(2, 1, 0.04f, 7), b = grid(2, 1, 0.04f, 3);
  GarmentMesh g = a;
  g.num_vertices = a.num_vertices + b.num_vertices;
  g.faces.resize(a.faces.rows() + b.faces.rows(), 3);
  g.faces << a.faces, (b.faces.array() + a.num_vertices).matrix();
  g.uv.resize(a.uv.rows() + b.uv.rows(), 2);
  g.uv << a.uv, b.uv;
  g.panel.insert(g.panel.end(), b.panel.begin(), b.panel.end());
  const PatchStructure s = build_patches(g, 0.04f);
  ASSERT_EQ(s.num_patches, 4);
  EXPECT_EQ(s.patch_panel, (std::vector<int32_t>{3, 3, 7, 7}));
  EXPECT_EQ(row(s.patch_vertices, 0), (std::vector<int32_t>{6, 7, 9, 10}));  // panel 3 first
  EXPECT_EQ(s.own_patch[0], 2);
  EXPECT_EQ(row(s.adjacency, 0), (std::vector<int32_t>{0, 1}));  // panels do not touch
}

TEST(Patches, PatchStateIsTheMeanOfMemberVertices) {
  const PatchStructure s = build_patches(grid(2, 1, 0.04f), 0.04f);
  Points x(6, 3);
  for (int v = 0; v < 6; ++v) x.row(v) << v, 2.f * v, 1.f;
  const auto m = patch_means(s, x);
  ASSERT_EQ(m.rows(), 2);
  EXPECT_FLOAT_EQ(m(0, 0), (0 + 1 + 3 + 4) / 4.f);
  EXPECT_FLOAT_EQ(m(1, 1), 2.f * (1 + 2 + 4 + 5) / 4.f);
  EXPECT_FLOAT_EQ(m(1, 2), 1.f);
}

TEST(Patches, IsolatedVertexHasNoPatch) {
  GarmentMesh g = grid(1, 1, 0.04f);
  g.num_vertices += 1;  // vertex 4 in no face
  const PatchStructure s = build_patches(g, 0.04f);
  EXPECT_EQ(s.own_patch[4], -1);
  EXPECT_EQ(s.vertex_patches.size(4), 0);
}

TEST(Patches, SyntheticTubeCoversEveryVertexWithDenseIds) {
  SyntheticOptions o;
  o.rings = 6;
  o.segments = 16;
  const Sequence seq = make_synthetic_sequence(o);
  const PatchStructure s = build_patches(seq.info.garments[0]);
  EXPECT_GT(s.num_patches, 2);
  for (int v = 0; v < s.num_vertices; ++v) EXPECT_GE(s.own_patch[v], 0);
  for (int p = 0; p < s.num_patches; ++p) EXPECT_GT(s.patch_vertices.size(p), 0);
  // Seam vertices (columns 0 and 8) are shared by both panels' patches.
  const int first_panel1 = static_cast<int>(std::find(s.patch_panel.begin(), s.patch_panel.end(), 1) -
                                            s.patch_panel.begin());
  EXPECT_GE(s.vertex_patches.end(0)[-1], first_panel1);
}

}  // namespace
}  // namespace layersnet::dataset
