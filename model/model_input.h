#pragma once
// Everything one LayersNet forward needs for one frame t -> t+1, already reduced to dense
// arrays and index lists (no geometry queries happen inside the forward).
//
// Dimension letters (used in every model/ and losses/ header):
//   N garment vertices, P patches, A attribute tokens, U body tokens (the body vertices that
//   some patch, vertex or patch centre refers to), G garments, F garment faces.
//   All matrices are row-major, flattened into std::vector<T>.
//
// Positions are in scene units and ROOT-RELATIVE: the body's root translation of the same
// frame is subtracted from every garment and body position (as the official code does),
// so shifting the whole scene changes no entry here except `root_*` tokens' absolute parts
// (which are velocities/accelerations, also shift-free).
//
// CSR lists: `x_offsets` has (rows + 1) entries, offsets[0] = 0, non-decreasing; row i's
// entries are x_items[offsets[i] .. offsets[i+1]). Empty rows are allowed.
//
// Optional parts: `has_wind == false` means there is no wind token at all (no encoder run,
// no attention slot, no RET edge). The root motion that the official wind token also
// carries is part of the (always present) gravity token instead (see model/README.md).
#include <cstdint>
#include <vector>

namespace layersnet::model {

inline constexpr int kVertexLocalDim = 21;  // columns of ModelInput::vertex_local

template <class T>
struct ModelInput {
  int64_t N = 0, P = 0, A = 0, U = 0;

  // ---- garment vertices -------------------------------------------------------------------
  // [x_t, v_t, x_{t-1}, v_{t-1}] root-relative, scene units and units/frame.   (N, 12)
  std::vector<T> state;
  // The same, normalised per column: (state - mean12) / std12.                 (N, 12)
  std::vector<T> state_norm;
  // Vertex -> patch membership (a vertex may be in several patches).  CSR over N.
  std::vector<int32_t> v2p_offsets, v2p_patches;
  // The vertex's own patch: the lowest patch id containing it (official argmax).  (N)
  std::vector<int32_t> own_patch;

  // ---- patches ------------------------------------------------------------------------------
  // Patch -> member vertices (the transpose of v2p).  CSR over P.
  std::vector<int32_t> p2v_offsets, p2v_vertices;
  // Mean of member vertex states: raw (P, 12) and normalised (P, 12).
  std::vector<T> patch_state, patch_norm;
  // Mesh-adjacent patches (incl. the patch itself, as official `patchwise`).  CSR over P, items in [0, P).
  std::vector<int32_t> mesh_offsets, mesh_senders;
  // World neighbours: centre distance < R, minus mesh-adjacent ones.  CSR over P, items in [0, P).
  std::vector<int32_t> world_offsets, world_senders;
  // The attribute token of each patch's garment.                        (P) in [0, A)
  std::vector<int32_t> patch_attr;

  // ---- attribute tokens ------------------------------------------------------------------------
  std::vector<T> attr;  // (A, 5) min-max normalised garment attributes (official read_garment_attributes)

  // ---- body tokens --------------------------------------------------------------------------------
  // Normalised body state [x_{t+1}, v_{t+1}, x_t, v_t] of each referenced body vertex.  (U, 12)
  std::vector<T> body_norm;
  // World -> local rotation of the body vertex normal frame (rows x, y, n).            (U, 9)
  std::vector<T> body_rot;
  // Body neighbours of each patch (ball query, radius R_b).  CSR over P, items in [0, U).
  std::vector<int32_t> body_offsets, body_tokens;

  // ---- wind and gravity -----------------------------------------------------------------------------
  bool has_wind = false;
  // [q_w, q_x, q_y, q_z, strength/400] at t+1 then t.                                    (1, 10)
  std::vector<T> wind;
  std::vector<T> wind_rot;  // (9) quaternion rotation at t (world -> wind frame)
  // ModelConfig::wind_force_input: the face wind of t+1 at x_t, (strength / 400) × the wind's unit
  // direction through dataset::face_wind_force, divided by the garment's mean vertex area share,
  // world axes; its patch means. Empty when off or without wind.          (N, 3) / (P, 3)
  std::vector<T> wind_force, wind_force_patch;
  // [g_acc(t+1), g_acc(t), root_vel(t+1), root_acc(t+1), root_vel(t), root_acc(t)], where
  // g_acc = (g/fps - root_acc - mu_acc)/sigma_acc and root_* normalised with the root stats.  (1, 18)
  std::vector<T> gravity;
  std::vector<T> gravity_rot;  // (9) frame of the unit gravity direction at t

  // ---- decoder ---------------------------------------------------------------------------------------------
  // Nearest body token of each patch centre / vertex, or -1 when farther than R_b
  // (then: identity frame, zero body feature).                         (P) / (N) in [-1, U)
  std::vector<int32_t> patch_body, vertex_body;
  // Candidate patches of each vertex that passed the validity test (<= 4, as the official decoder).
  // CSR over N, items in [0, P). An empty row gives a zero relative acceleration.
  std::vector<int32_t> cand_offsets, cand_patches;
  // Local features of each vertex for the decoder (ModelConfig::vertex_local_features; empty
  // when off), world axes, seven 3-vectors:                                    (N, 21)
  //   x_t − b_t, b'_{t+1} − v_t, b'_{t+1} − b'_t      the nearest body vertex b (zero if none
  //                                                   within R_b), b' its velocity; / R_b, / σ_v, / σ_v
  //   Σ_j (|e_j| − l_j) / |e_j| e_j, mean_j e_j       e_j = x_j − x_v over the mesh neighbours j,
  //                                                   l_j rest length: spring force, Laplacian; / R_b
  //   mean_j (v_j − v_v), v_t − v_{t−1}               velocity Laplacian, last acceleration; / σ_v
  // σ_v the mean velocity std (std12 columns 3..5). The decoder rotates each 3-vector into the
  // vertex's body frame, so the features keep the model rotation-equivariant.
  std::vector<T> vertex_local;
  // The velocity base of ModelConfig::velocity_base "body" (the body-carried displacement of each
  // vertex from t to t+1, TrainingSample::body_carry) or "body_inertia" (that plus the vertex's
  // velocity relative to the body at t); root-relative, units/frame.  (N, 3) or empty
  std::vector<T> body_carry;
  // body_carry averaged over each patch's member vertices (dataset::patch_means).  (P, 3) or empty
  std::vector<T> body_carry_patch;
  // Garment mesh neighbours of each vertex, for ModelConfig::output_smoothing (empty when it is
  // 0). A vertex without mesh neighbours lists itself, so averaging keeps its value.  CSR over N.
  std::vector<int32_t> vertex_mesh_offsets, vertex_mesh_neighbours;
  // The physics step's linear system at its result, for ModelConfig::physics_step_correction =
  // "solved" (TrainingSample::physics_system; empty otherwise): a symmetric positive-definite
  // matrix of 3×3 blocks, CSR over the N vertices, and the inertia weight of each vertex.
  std::vector<int32_t> system_offsets, system_columns;  // (N+1), (nnz)
  std::vector<T> system_blocks, system_scale;           // (nnz · 9) row-major, (N)

  // ---- statistics -----------------------------------------------------------------------------------------
  // Per-column mean and std of the 12-d state ([pos, vel] stats repeated for both frames).
  std::vector<T> mean12, std12;
};

// The same input in another precision (e.g. double for gradient checks).
template <class U, class T>
ModelInput<U> cast_input(const ModelInput<T>& in) {
  auto cv = [](const std::vector<T>& v) { return std::vector<U>(v.begin(), v.end()); };
  ModelInput<U> o;
  o.N = in.N, o.P = in.P, o.A = in.A, o.U = in.U;
  o.state = cv(in.state), o.state_norm = cv(in.state_norm);
  o.v2p_offsets = in.v2p_offsets, o.v2p_patches = in.v2p_patches, o.own_patch = in.own_patch;
  o.p2v_offsets = in.p2v_offsets, o.p2v_vertices = in.p2v_vertices;
  o.patch_state = cv(in.patch_state), o.patch_norm = cv(in.patch_norm);
  o.mesh_offsets = in.mesh_offsets, o.mesh_senders = in.mesh_senders;
  o.world_offsets = in.world_offsets, o.world_senders = in.world_senders;
  o.patch_attr = in.patch_attr, o.attr = cv(in.attr);
  o.body_norm = cv(in.body_norm), o.body_rot = cv(in.body_rot);
  o.body_offsets = in.body_offsets, o.body_tokens = in.body_tokens;
  o.has_wind = in.has_wind, o.wind = cv(in.wind), o.wind_rot = cv(in.wind_rot);
  o.wind_force = cv(in.wind_force), o.wind_force_patch = cv(in.wind_force_patch);
  o.gravity = cv(in.gravity), o.gravity_rot = cv(in.gravity_rot);
  o.patch_body = in.patch_body, o.vertex_body = in.vertex_body;
  o.cand_offsets = in.cand_offsets, o.cand_patches = in.cand_patches;
  o.vertex_local = cv(in.vertex_local);
  o.body_carry = cv(in.body_carry), o.body_carry_patch = cv(in.body_carry_patch);
  o.vertex_mesh_offsets = in.vertex_mesh_offsets, o.vertex_mesh_neighbours = in.vertex_mesh_neighbours;
  o.system_offsets = in.system_offsets, o.system_columns = in.system_columns;
  o.system_blocks = cv(in.system_blocks), o.system_scale = cv(in.system_scale);
  o.mean12 = cv(in.mean12), o.std12 = cv(in.std12);
  return o;
}

// Throws (naming the field and the fix) unless every size and index is consistent.
template <class T>
void validate(const ModelInput<T>& in);

}  // namespace layersnet::model
