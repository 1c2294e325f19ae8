#include "dataset/wind.h"

namespace layersnet::dataset {

Eigen::Matrix3f quaternion_matrix(const Eigen::Vector4f& q) {
  const float n = q.norm();
  if (!(n > 0)) return Eigen::Matrix3f::Identity();
  return Eigen::Quaternionf(q[0] / n, q[1] / n, q[2] / n, q[3] / n).toRotationMatrix();
}

Eigen::Vector3f wind_direction(const Eigen::Vector4f& q) { return quaternion_matrix(q).col(2); }

std::vector<WindSegment> wind_segments(const SequenceInfo& info) {
  std::vector<WindSegment> out;
  if (!info.has_wind) return out;
  for (int t = 0; t < info.num_frames; ++t) {
    const Eigen::Vector4f q = info.wind_rotation.row(t).transpose();
    const float s = info.wind_strength[t];
    if (!out.empty() && (out.back().rotation - q).cwiseAbs().maxCoeff() <= 1e-6f &&
        std::abs(out.back().strength - s) <= 1e-6f) {
      out.back().end = t + 1;
      continue;
    }
    out.push_back({t, t + 1, s, q, wind_direction(q)});
  }
  return out;
}

}  // namespace layersnet::dataset
