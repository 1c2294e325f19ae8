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

Points face_wind_force(const Points& x, const std::vector<int32_t>& faces, const Eigen::Vector3d& w,
                       Eigen::VectorXd* vertex_area) {
  const Eigen::Index N = x.rows();
  Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor> force = Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor>::Zero(N, 3);
  if (vertex_area) vertex_area->setZero(N);
  for (std::size_t f = 0; f + 2 < faces.size(); f += 3) {
    const Eigen::Vector3d p0 = x.row(faces[f]).transpose().cast<double>();
    const Eigen::Vector3d cr = (x.row(faces[f + 1]).transpose().cast<double>() - p0)
                                   .cross(x.row(faces[f + 2]).transpose().cast<double>() - p0);
    const double area = cr.norm() / 2;
    if (!(area > 0)) continue;
    const Eigen::Vector3d n = cr / (2 * area);
    const Eigen::Vector3d corner = area / 3.0 * w.dot(n) * n;
    for (int c = 0; c < 3; ++c) {
      force.row(faces[f + c]) += corner.transpose();
      if (vertex_area) (*vertex_area)[faces[f + c]] += area / 3.0;
    }
  }
  return force.cast<float>();
}

}  // namespace layersnet::dataset
