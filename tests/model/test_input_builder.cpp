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

// The builder uses the data layer's grid / k-d tree; here the brute-force definitions:
// body lists = the K nearest body vertices (t+1) within R_b of each patch centre, and
// patch_body / vertex_body = the nearest body vertex if within R_b.
TEST(InputBuilder, BodyListsAndNearestFollowTheirDefinitions) {
  auto c = testing::tiny_config();
  const auto scene = make_synthetic_scene(testing::tiny_scene());
  const auto in = build_model_input(scene, c);
  const int64_t B = scene.B;
  auto body = [&](int64_t b) {
    return Eigen::Vector3d(scene.body_tp1[3 * b] - scene.root[3][0], scene.body_tp1[3 * b + 1] - scene.root[3][1],
                           scene.body_tp1[3 * b + 2] - scene.root[3][2]);
  };
  // Token -> body vertex, from the token's de-normalised position x_{t+1}.
  std::vector<int64_t> vertex_of(in.U, -1);
  for (int64_t u = 0; u < in.U; ++u) {
    Eigen::Vector3d x;
    for (int k = 0; k < 3; ++k) x[k] = in.body_norm[12 * u + k] * in.std12[k] + in.mean12[k];
    for (int64_t b = 0; b < B; ++b)
      if ((body(b) - x).norm() < 1e-9) vertex_of[u] = b;
    ASSERT_GE(vertex_of[u], 0) << "token " << u;
  }
  auto nearest = [&](const Eigen::Vector3d& q) {
    int64_t best = 0;
    for (int64_t b = 1; b < B; ++b)
      if ((body(b) - q).norm() < (body(best) - q).norm()) best = b;
    return best;
  };
  for (int64_t p = 0; p < in.P; ++p) {
    const Eigen::Vector3d cp(&in.patch_state[12 * p]);
    std::vector<std::pair<double, int64_t>> hits;
    for (int64_t b = 0; b < B; ++b)
      if ((body(b) - cp).norm() < c.body_radius) hits.emplace_back((body(b) - cp).norm(), b);
    std::sort(hits.begin(), hits.end());
    hits.resize(std::min<std::size_t>(hits.size(), static_cast<std::size_t>(c.body_neighbors)));
    std::vector<int64_t> want, got;
    for (const auto& h : hits) want.push_back(h.second);
    for (int k = in.body_offsets[p]; k < in.body_offsets[p + 1]; ++k) got.push_back(vertex_of[in.body_tokens[k]]);
    EXPECT_EQ(got, want) << "patch " << p;
    const int64_t nb = nearest(cp);
    EXPECT_EQ(in.patch_body[p] >= 0, (body(nb) - cp).norm() < c.body_radius) << "patch " << p;
    if (in.patch_body[p] >= 0) {
      EXPECT_EQ(vertex_of[in.patch_body[p]], nb) << "patch " << p;
    }
  }
  int near_vertices = 0;
  for (int64_t v = 0; v < in.N; ++v) {
    const Eigen::Vector3d x(in.state[12 * v], in.state[12 * v + 1], in.state[12 * v + 2]);
    const int64_t nb = nearest(x);
    const bool within = (body(nb) - x).norm() < c.body_radius;
    EXPECT_EQ(in.vertex_body[v] >= 0, within) << "vertex " << v;
    if (within) {
      EXPECT_EQ(vertex_of[in.vertex_body[v]], nb) << "vertex " << v;
      ++near_vertices;
    }
  }
  EXPECT_GT(near_vertices, 0);
}

}  // namespace
}  // namespace layersnet::model
