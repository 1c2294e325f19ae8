#include "model/model_input.h"

#include "autodiff/check.h"

#include <string>

namespace layersnet::model {
namespace {

void check_size(const char* field, std::size_t got, int64_t want) {
  LAYERSNET_CHECK(static_cast<int64_t>(got) == want, "ModelInput." << field << " has " << got << " entries, expected "
                                                                   << want << " (fix the input builder)");
}

void check_csr(const char* field, const std::vector<int32_t>& offsets, const std::vector<int32_t>& items, int64_t rows,
               int64_t lo, int64_t bound) {
  check_size(field, offsets.size(), rows + 1);
  LAYERSNET_CHECK(offsets.front() == 0 && offsets.back() == static_cast<int32_t>(items.size()),
                  "ModelInput." << field << ": CSR offsets must start at 0 and end at the item count " << items.size());
  for (int64_t r = 0; r < rows; ++r)
    LAYERSNET_CHECK(offsets[r] <= offsets[r + 1], "ModelInput." << field << ": offsets decrease at row " << r);
  for (std::size_t k = 0; k < items.size(); ++k)
    LAYERSNET_CHECK(items[k] >= lo && items[k] < bound, "ModelInput." << field << ": item " << k << " = " << items[k]
                                                                      << " outside [" << lo << ", " << bound << ")");
}

void check_index(const char* field, const std::vector<int32_t>& idx, int64_t n, int64_t lo, int64_t bound) {
  check_size(field, idx.size(), n);
  for (std::size_t k = 0; k < idx.size(); ++k)
    LAYERSNET_CHECK(idx[k] >= lo && idx[k] < bound, "ModelInput." << field << "[" << k << "] = " << idx[k]
                                                                  << " outside [" << lo << ", " << bound << ")");
}

}  // namespace

template <class T>
void validate(const ModelInput<T>& in) {
  const int64_t N = in.N, P = in.P, A = in.A, U = in.U;
  LAYERSNET_CHECK(N > 0 && P > 0 && A > 0, "ModelInput: needs N, P, A > 0, got " << N << ", " << P << ", " << A);
  check_size("state", in.state.size(), N * 12);
  check_size("state_norm", in.state_norm.size(), N * 12);
  check_csr("v2p", in.v2p_offsets, in.v2p_patches, N, 0, P);
  check_index("own_patch", in.own_patch, N, 0, P);
  check_csr("p2v", in.p2v_offsets, in.p2v_vertices, P, 0, N);
  check_size("patch_state", in.patch_state.size(), P * 12);
  check_size("patch_norm", in.patch_norm.size(), P * 12);
  check_csr("mesh", in.mesh_offsets, in.mesh_senders, P, 0, P);
  check_csr("world", in.world_offsets, in.world_senders, P, 0, P);
  check_index("patch_attr", in.patch_attr, P, 0, A);
  check_size("attr", in.attr.size(), A * 5);
  check_size("body_norm", in.body_norm.size(), U * 12);
  check_size("body_rot", in.body_rot.size(), U * 9);
  check_csr("body", in.body_offsets, in.body_tokens, P, 0, U);
  if (in.has_wind) {
    check_size("wind", in.wind.size(), 10);
    check_size("wind_rot", in.wind_rot.size(), 9);
  }
  check_size("gravity", in.gravity.size(), 18);
  check_size("gravity_rot", in.gravity_rot.size(), 9);
  check_index("patch_body", in.patch_body, P, -1, U);
  check_index("vertex_body", in.vertex_body, N, -1, U);
  check_csr("cand", in.cand_offsets, in.cand_patches, N, 0, P);
  if (!in.wind_force.empty() || !in.wind_force_patch.empty()) {
    check_size("wind_force", in.wind_force.size(), N * 3);
    check_size("wind_force_patch", in.wind_force_patch.size(), P * 3);
  }
  if (!in.vertex_local.empty()) check_size("vertex_local", in.vertex_local.size(), N * kVertexLocalDim);
  if (!in.body_carry.empty()) check_size("body_carry", in.body_carry.size(), N * 3);
  if (!in.body_carry.empty() || !in.body_carry_patch.empty())
    check_size("body_carry_patch", in.body_carry_patch.size(), P * 3);
  if (!in.vertex_mesh_offsets.empty()) check_csr("vertex_mesh", in.vertex_mesh_offsets, in.vertex_mesh_neighbours, N, 0, N);
  if (!in.system_offsets.empty()) {
    check_csr("system", in.system_offsets, in.system_columns, N, 0, N);
    check_size("system_blocks", in.system_blocks.size(), static_cast<int64_t>(in.system_columns.size()) * 9);
    check_size("system_scale", in.system_scale.size(), N);
  }
  check_size("mean12", in.mean12.size(), 12);
  check_size("std12", in.std12.size(), 12);
}

template void validate(const ModelInput<float>&);
template void validate(const ModelInput<double>&);

}  // namespace layersnet::model
