// The input builder: frames, quaternions, neighbour lists against their definitions.
#include "model/input_builder.h"
#include "model_test_util.h"

#include <gtest/gtest.h>

#include <Eigen/Core>
#include <Eigen/LU>

#include <algorithm>
#include <cmath>
#include <random>

namespace layersnet::model {
namespace {

using Mat3 = Eigen::Matrix<double, 3, 3, Eigen::RowMajor>;

TEST(InputBuilder, NormalFramesAreRotationsWithTheNormalLast) {
  std::vector<Eigen::Vector3d> normals = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}, {-1, 0, 0}, {0, 0, -1},
                                          {1, 1e-8, 0}, {1e-9, -1e-9, 1}, {1, 1, 1}, {0, 1, 1e-6}};
  std::mt19937_64 rng(1);
  std::normal_distribution<double> g(0, 1);
  for (int k = 0; k < 200; ++k) normals.push_back({g(rng), g(rng), g(rng)});
  for (auto n : normals) {
    n.normalize();
    double R[9];
    normal_frame(n.data(), R);
    const Eigen::Map<const Mat3> M(R);
    EXPECT_LT((M * M.transpose() - Mat3::Identity()).norm(), 1e-12) << n.transpose();
    EXPECT_NEAR(M.determinant(), 1.0, 1e-12);
    EXPECT_LT((M.row(2).transpose() - n).norm(), 1e-12);  // R n = e_z
  }
  const double zero[3] = {0, 0, 0};
  double R[9];
  normal_frame(zero, R);
  EXPECT_EQ(Eigen::Map<const Mat3>(R), Mat3::Identity());
}

TEST(InputBuilder, QuaternionRotations) {
  const double half[4] = {std::cos(0.25), 0, 0, std::sin(0.25)};  // 0.5 rad about z
  double R[9];
  quaternion_to_rotation(half, R);
  EXPECT_NEAR(R[0], std::cos(0.5), 1e-12);
  EXPECT_NEAR(R[3], std::sin(0.5), 1e-12);  // x axis -> (cos, sin, 0)
  const double zero[4] = {0, 0, 0, 0};
  quaternion_to_rotation(zero, R);
  EXPECT_EQ(Eigen::Map<const Mat3>(R), Mat3::Identity());
}

TEST(InputBuilder, NeighbourListsFollowTheirDefinitions) {
  auto c = testing::tiny_config();
  const auto scene = make_synthetic_scene(testing::tiny_scene());
  const auto in = build_model_input(scene, c);
  auto centre = [&](int p) { return Eigen::Vector3d(&in.patch_state[12 * p]); };
  for (int i = 0; i < in.P; ++i) {
    const auto mb = in.mesh_senders.begin() + in.mesh_offsets[i], me = in.mesh_senders.begin() + in.mesh_offsets[i + 1];
    EXPECT_NE(std::find(mb, me, i), me) << "a patch is mesh-adjacent to itself";
    for (int j = 0; j < in.P; ++j) {
      const bool near = j != i && (centre(i) - centre(j)).norm() < c.world_radius && std::find(mb, me, j) == me;
      const auto wb = in.world_senders.begin() + in.world_offsets[i], we = in.world_senders.begin() + in.world_offsets[i + 1];
      EXPECT_EQ(near, std::find(wb, we, j) != we) << i << " -> " << j;
    }
    EXPECT_LE(in.body_offsets[i + 1] - in.body_offsets[i], c.body_neighbors);
  }
  EXPECT_GT(in.world_senders.size(), 0u);
  EXPECT_GT(in.body_tokens.size(), 0u);
  // Decoder candidates: at most 4, all mesh-adjacent to the vertex's own patch.
  for (int v = 0; v < in.N; ++v) {
    const int own = in.own_patch[v];
    EXPECT_LE(in.cand_offsets[v + 1] - in.cand_offsets[v], c.decoder_patch_candidates);
    for (int k = in.cand_offsets[v]; k < in.cand_offsets[v + 1]; ++k) {
      const auto mb = in.mesh_senders.begin() + in.mesh_offsets[own], me = in.mesh_senders.begin() + in.mesh_offsets[own + 1];
      EXPECT_NE(std::find(mb, me, in.cand_patches[k]), me);
    }
  }
  // Patch states are the means of their members' states.
  for (int p = 0; p < in.P; ++p) {
    double sum = 0;
    for (int k = in.p2v_offsets[p]; k < in.p2v_offsets[p + 1]; ++k) sum += in.state[12 * in.p2v_vertices[k] + 4];
    EXPECT_NEAR(in.patch_state[12 * p + 4], sum / (in.p2v_offsets[p + 1] - in.p2v_offsets[p]), 1e-12);
  }
}

}  // namespace
}  // namespace layersnet::model
