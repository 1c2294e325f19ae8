#pragma once
// One training/inference window of a scene in WORLD coordinates (double), the raw material
// from which build_model_input() derives a ModelInput (root-relative states, neighbour
// lists, frames) and build_loss_input() the ground truth for the losses.
//
// Dimension letters: N garment vertices, F garment faces, G garments, P patches,
// B body vertices, Fb body faces. Frames: t is the current frame; the model predicts t+1.
// Positions in scene units; velocities and accelerations per frame (dt = 1, official).
#include <cstdint>
#include <vector>

namespace layersnet::model {

struct SceneStats {
  double pos_mean[3] = {0, 0, 0}, pos_std[3] = {1, 1, 1};  // garment+body positions (root-relative)
  double vel_mean[3] = {0, 0, 0}, vel_std[3] = {1, 1, 1};  // garment+body velocities
  double acc_mean[3] = {0, 0, 0}, acc_std[3] = {1, 1, 1};  // garment+body accelerations (gravity token)
  double root_vel_mean[3] = {0, 0, 0}, root_vel_std[3] = {1, 1, 1};
  double root_acc_mean[3] = {0, 0, 0}, root_acc_std[3] = {1, 1, 1};
};

struct SceneWindow {
  int64_t N = 0, P = 0, B = 0;

  // ---- garments (world coordinates) --------------------------------------------------------
  std::vector<double> x_tm2, x_tm1, x_t;  // (N, 3) at t-2, t-1, t
  std::vector<double> x_tp1;              // (N, 3) at t+1: ground truth (may be empty at inference)
  std::vector<int32_t> faces;             // (F, 3) global vertex ids, counter-clockwise
  std::vector<int32_t> garment_offsets;   // (G + 1) vertex ranges, inner -> outer (last = outer)
  std::vector<double> garment_attr;       // (G, 5) normalised attributes (official read_garment_attributes)

  // ---- patches (static per garment set) ---------------------------------------------------------
  std::vector<int32_t> v2p_offsets, v2p_patches;    // CSR over N
  std::vector<int32_t> p2v_offsets, p2v_vertices;   // CSR over P
  std::vector<int32_t> own_patch;                   // (N)
  std::vector<int32_t> adj_offsets, adj_patches;    // CSR over P, mesh adjacency incl. self
  std::vector<int32_t> patch_garment;               // (P) in [0, G)

  // ---- body (world coordinates) -----------------------------------------------------------------
  std::vector<double> body_tm1, body_t, body_tp1;   // (B, 3) at t-1, t, t+1
  std::vector<int32_t> body_faces;                  // (Fb, 3)

  // ---- root translation and wind -------------------------------------------------------------------
  double root[4][3] = {};  // root translation at t-2, t-1, t, t+1
  bool has_wind = false;
  double wind_tp1[5] = {1, 0, 0, 0, 0}, wind_t[5] = {1, 0, 0, 0, 0};  // [qw, qx, qy, qz, strength/400]
  double fps = 30.0;
  double gravity[3] = {0, 0, -9.8};  // m/s² in scene axes (+z up); the token uses g/fps (official)

  SceneStats stats;
};

}  // namespace layersnet::model
