#pragma once
// Wind helpers (spec: /wind/rotation unit quaternions (w, x, y, z), /wind/strength; the wind
// blows along R(q)·(0, 0, 1), uniform in space, piecewise constant in D-LAYERS).
#include "dataset/sequence.h"

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <vector>

namespace layersnet::dataset {

// Direction the wind blows along at frame t: R(q_t)·(0, 0, 1) (unit). q: (w, x, y, z).
Eigen::Vector3f wind_direction(const Eigen::Vector4f& q_wxyz);
// Rotation matrix of a (w, x, y, z) quaternion; an all-zero quaternion gives the identity
// (as scipy in the official code).
Eigen::Matrix3f quaternion_matrix(const Eigen::Vector4f& q_wxyz);

// A run of frames [begin, end) with the same wind (rotation and strength within 1e-6).
struct WindSegment {
  int begin = 0, end = 0;
  float strength = 0.f;          // 0 = no wind
  Eigen::Vector4f rotation{1, 0, 0, 0};
  Eigen::Vector3f direction{0, 0, 1};
};
// Segments of a sequence; empty when the sequence has no /wind group.
std::vector<WindSegment> wind_segments(const SequenceInfo& info);

// The shape of Blender's face wind (implicit_blender.c) without its 0.02: each triangle gives each
// of its corners area/3 · (w·n) n, n its unit normal at x (the sign of n cancels), so cloth
// edge-on to the wind feels none. x (N, 3) positions, faces (F·3) vertex ids into x, w the wind
// vector. Returns (N, 3), units² of x times w's units. vertex_area, when given, receives each
// vertex's share Σ area/3 (N).
Points face_wind_force(const Points& x, const std::vector<int32_t>& faces, const Eigen::Vector3d& w,
                       Eigen::VectorXd* vertex_area = nullptr);

}  // namespace layersnet::dataset
