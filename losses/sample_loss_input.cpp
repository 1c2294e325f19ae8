#include "losses/sample_loss_input.h"

#include "autodiff/check.h"
#include "dataset/neighbours.h"

namespace layersnet::losses {

LossInput<float> loss_input_from_sample(const dataset::TrainingSample& s, const dataset::SequenceInfo& info) {
  LAYERSNET_CHECK(s.structure != nullptr && static_cast<int>(s.structure->vertex_offsets.size()) == info.num_garments() + 1,
                  "loss_input_from_sample: sample '" << s.sequence_id << "' does not match the SequenceInfo's garments");
  const auto& st = *s.structure;
  const int64_t N = s.num_vertices(), P = s.num_patches(), B = s.body_state.rows();
  LossInput<float> L;
  dataset::PointsD target(N, 3);  // normals summed in double
  L.target.resize(N * 3);
  for (int64_t v = 0; v < N; ++v)
    for (int c = 0; c < 3; ++c) L.target[3 * v + c] = s.target(v, c), target(v, c) = s.target(v, c);
  L.target_patch.resize(P * 3);
  for (int64_t p = 0; p < P; ++p)
    for (int c = 0; c < 3; ++c) L.target_patch[3 * p + c] = s.target_patch_centre(p, c);
  for (int g = 0; g < info.num_garments(); ++g) {
    const auto& f = info.garments[g].faces;
    for (Eigen::Index i = 0; i < f.rows(); ++i)
      for (int k = 0; k < 3; ++k) L.faces.push_back(f(i, k) + st.vertex_offsets[g]);
  }
  const dataset::PointsD normals = dataset::vertex_normals(
      target, Eigen::Map<const dataset::Faces>(L.faces.data(), static_cast<Eigen::Index>(L.faces.size() / 3), 3));
  L.target_normals.assign(normals.data(), normals.data() + normals.size());
  L.garment_offsets = st.vertex_offsets;
  set_target_edges(L);
  L.body_pos.resize(B * 3);
  L.body_normals.resize(B * 3);
  for (int64_t b = 0; b < B; ++b)
    for (int c = 0; c < 3; ++c) L.body_pos[3 * b + c] = s.body_state(b, c), L.body_normals[3 * b + c] = s.body_normals_next(b, c);
  return L;
}

}  // namespace layersnet::losses
