#pragma once
// LayersNet training losses (paper eq. 16–19, as the official losses define them), on the
// tape, for one sample:
//
//   vertex      Σ_v ‖x̂_v − x_v‖² / N                                    (eq. 16, garment vertices)
//   patch       Σ_p ‖ĉ_p − c_p‖² / P, c_p = mean of GT member vertices   (eq. 16, patch centres)
//   normal      Σ_v ‖n̂_v − n_v‖² / N, vertex normal = normalised sum of unit face normals (eq. 17)
//   collision_body   Σ_v min((x̂_v − h_a)·n_a − d_ε, 0)² / N_c, a = nearest GT body vertex at t+1,
//                    N_c = number of vertices with a non-zero term (eq. 18)
//   collision_layer  the same for the outer (last) garment's vertices against the nearest
//                    vertex of all inner garments, with the PREDICTED inner normals (eq. 18);
//                    with loss.layer_mean_over = "outer" the sum is divided by every outer vertex
//   orthogonality    Σ_W ‖W Wᵀ − I‖²_F + ‖Wᵀ W − I‖²_F over every RET map W (eq. 9 as a penalty);
//                    absent with model.orthogonality = "exact" (W orthonormal by construction)
//   edge_strain      Σ_e ((‖x̂_i − x̂_j‖ − l_e) / l_e)² / E over the garment edges, l_e the ground-truth
//                    length at t+1 (not in the paper; off by default)
//
//   total = Σ weight_k · term_k, weights from LossConfig (collision_layer is NOT multiplied by
//   collision_body, as in the official code). With relative_to_base, vertex and patch are
//   divided by the same error of the zero-output prediction x − a (not in the paper).
//
// Nearest anchors are found outside the tape on the current values (indices only); the
// distances are on the tape. A term whose weight is 0, or that the scene does not have
// (one garment -> no layer term; no RET -> no orthogonality), records no op at all.
#include "autodiff/params.h"
#include "autodiff/tape.h"
#include "model/layersnet.h"
#include "model/model_config.h"
#include "model/model_input.h"

#include <cstdint>
#include <string>
#include <vector>

namespace layersnet::losses {

// Ground truth of one sample (root-relative at t+1, the frame of the predictions).
// N garment vertices, P patches, F faces, G garments, B body vertices.
template <class T>
struct LossInput {
  std::vector<T> target;          // (N, 3) x_{t+1}
  std::vector<T> target_patch;    // (P, 3) mean of GT member vertices
  std::vector<T> target_normals;  // (N, 3) GT vertex normals
  std::vector<int32_t> faces;     // (F, 3)
  std::vector<int32_t> garment_offsets;  // (G + 1), inner -> outer
  std::vector<T> body_pos;        // (B, 3) GT body at t+1
  std::vector<T> body_normals;    // (B, 3) its vertex normals
  std::vector<int32_t> edges;     // (E, 2) unique garment edges, global vertex ids (from faces)
  std::vector<T> target_edge_length;  // (E) ground-truth lengths at t+1, scene units
};

// Fills L.edges and L.target_edge_length from L.faces and L.target.
template <class T>
void set_target_edges(LossInput<T>& L);

template <class U, class T>
LossInput<U> cast_loss_input(const LossInput<T>& in) {
  auto cv = [](const std::vector<T>& v) { return std::vector<U>(v.begin(), v.end()); };
  return {cv(in.target),    cv(in.target_patch), cv(in.target_normals), in.faces, in.garment_offsets,
          cv(in.body_pos),  cv(in.body_normals),  in.edges,               cv(in.target_edge_length)};
}

template <class T>
struct LossTerms {
  ad::Var<T> total;  // (1, 1), differentiable
  // Unweighted values of each term (0 when absent) for logging.
  double vertex = 0, patch = 0, normal = 0, collision_body = 0, collision_layer = 0, orthogonality = 0,
         edge_strain = 0;
  int64_t body_collisions = 0, layer_collisions = 0;  // N_c of each collision term
};

template <class T>
LossTerms<T> compute_losses(ad::Tape<T>& tape, ad::ParamStore<T>& params, const ModelConfig& model_config,
                            const LossConfig& loss_config, const LossInput<T>& target,
                            const model::Predictions<T>& pred);

}  // namespace layersnet::losses
