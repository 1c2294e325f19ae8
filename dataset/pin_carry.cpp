#include "dataset/pin_carry.h"

#include "dataset/garments.h"

#include <Eigen/SVD>

#include <algorithm>
#include <limits>
#include <numeric>
#include <stdexcept>
#include <string>

namespace layersnet::dataset {
namespace {

constexpr float kPinBandMetres = 0.05f;

std::vector<int32_t> pin_carriers(const std::vector<int32_t>& pinned_rows, const Eigen::Ref<const Points>& garments,
                                  const Eigen::Ref<const Points>& body, char up_axis, float scale) {
  const int up = up_axis == 'y' ? 1 : 2;
  const float band = kPinBandMetres * scale;
  Eigen::RowVector3f centre = Eigen::RowVector3f::Zero();
  float low = std::numeric_limits<float>::infinity(), high = -low;
  for (int32_t r : pinned_rows) {
    centre += garments.row(r);
    low = std::min(low, garments(r, up));
    high = std::max(high, garments(r, up));
  }
  centre /= static_cast<float>(pinned_rows.size());
  const auto across = [&](const Eigen::RowVector3f& p) {
    Eigen::RowVector3f d = p - centre;
    d[up] = 0.f;
    return d.norm();
  };
  float radius = 0.f;
  for (int32_t r : pinned_rows) radius += across(garments.row(r));
  radius /= static_cast<float>(pinned_rows.size());
  std::vector<int32_t> inside;
  for (Eigen::Index b = 0; b < body.rows(); ++b) {
    const Eigen::RowVector3f p = body.row(b);
    if (p[up] >= low - band && p[up] <= high + band && across(p) < radius) inside.push_back(static_cast<int32_t>(b));
  }
  if (inside.size() >= 3) return inside;
  std::vector<int32_t> near;
  for (Eigen::Index b = 0; b < body.rows(); ++b)
    if (std::any_of(pinned_rows.begin(), pinned_rows.end(),
                    [&](int32_t r) { return (body.row(b) - garments.row(r)).norm() <= band; }))
      near.push_back(static_cast<int32_t>(b));
  if (near.size() >= 3) return near;
  std::vector<int32_t> all(static_cast<size_t>(body.rows()));
  std::iota(all.begin(), all.end(), 0);
  return all;
}

}  // namespace

RigidMotion fit_rigid_motion(const Eigen::Ref<const Points>& from, const Eigen::Ref<const Points>& to,
                             const std::vector<int32_t>& rows) {
  Eigen::Vector3d mean_from = Eigen::Vector3d::Zero(), mean_to = Eigen::Vector3d::Zero();
  for (int32_t r : rows) {
    mean_from += from.row(r).transpose().cast<double>();
    mean_to += to.row(r).transpose().cast<double>();
  }
  mean_from /= static_cast<double>(rows.size());
  mean_to /= static_cast<double>(rows.size());
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();
  for (int32_t r : rows)
    covariance += (from.row(r).transpose().cast<double>() - mean_from) * (to.row(r).cast<double>() - mean_to.transpose());
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(covariance, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d flip = Eigen::Matrix3d::Identity();
  flip(2, 2) = (svd.matrixV() * svd.matrixU().transpose()).determinant() < 0 ? -1.0 : 1.0;
  RigidMotion m;
  m.rotation = svd.matrixV() * flip * svd.matrixU().transpose();
  m.translation = mean_to - m.rotation * mean_from;
  return m;
}

std::vector<PinGroup> pin_groups(const SequenceInfo& info, const Eigen::Ref<const Points>& garments,
                                 const Eigen::Ref<const Points>& body) {
  std::vector<PinGroup> groups;
  int64_t offset = 0;
  for (size_t g = 0; g < info.garments.size(); ++g) {
    const GarmentMesh& mesh = info.garments[g];
    PinGroup group;
    group.garment = static_cast<int32_t>(g);
    for (int v = 0; v < mesh.num_vertices; ++v)
      if (mesh.pinned(v)) group.rows.push_back(static_cast<int32_t>(offset + v));
    if (!group.rows.empty()) {
      group.carriers = pin_carriers(group.rows, garments, body, info.up_axis, info.scale);
      groups.push_back(std::move(group));
    }
    offset += mesh.num_vertices;
  }
  return groups;
}

int64_t carry_pins(const std::vector<PinGroup>& groups, const Eigen::Ref<const Points>& body_before,
                   const Eigen::Ref<const Points>& body, const Eigen::Ref<const Points>& x_before, Points& x) {
  int64_t moved = 0;
  for (const PinGroup& group : groups) {
    const RigidMotion m = fit_rigid_motion(body_before, body, group.carriers);
    for (int32_t r : group.rows) {
      x.row(r) = (m.rotation * x_before.row(r).transpose().cast<double>() + m.translation).transpose().cast<float>();
      ++moved;
    }
  }
  return moved;
}

void rig_pins(Sequence& seq, int reference) {
  const SequenceInfo& info = seq.info;
  if (reference < seq.frames.first || reference >= seq.frames.first + seq.frames.count)
    throw std::runtime_error(info.path + ": cannot rig the pins from frame " + std::to_string(reference) +
                             ", which is not among the frames loaded");
  const Points garments = garments_at(info, seq.frames, reference);
  const Points body_reference = seq.body_at(reference);
  // The body under the pins is chosen at the first frame loaded (a rest pose where the data has
  // one): at a later frame a hand or an arm may pass through the loop and be taken for the torso.
  const int choose = seq.frames.first;
  const std::vector<PinGroup> groups = pin_groups(info, garments_at(info, seq.frames, choose), seq.body_at(choose));
  const std::vector<int32_t> first_row = garment_layout(info).offsets;  // of each garment in the concatenation
  Points carried = garments;
  for (int t = reference + 1; t < seq.frames.first + seq.frames.count; ++t) {
    carry_pins(groups, body_reference, seq.body_at(t), garments, carried);
    for (const PinGroup& group : groups) {
      const Eigen::Index n = info.garments[static_cast<size_t>(group.garment)].num_vertices;
      Points& frames = seq.frames.garments[static_cast<size_t>(group.garment)];
      for (int32_t r : group.rows)
        frames.row((t - seq.frames.first) * n + r - first_row[static_cast<size_t>(group.garment)]) = carried.row(r);
    }
  }
  seq.info.pins_recorded = true;
}

}  // namespace layersnet::dataset
