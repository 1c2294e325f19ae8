#pragma once
// Training samples: the model inputs for (sequence, frame t) and the targets
// at t+1, following the official per-sample tensors
// (patch_layers_dynamic_dataset.py: normalisation, neighbourhoods, wind, attributes).
//
// Frames and units. Every position of frame f is relative to the body root translation
// r_f of the same frame (translation only). Velocities are per frame:
//   x̃_f = x_f - r_f,   v_f = x̃_f - x̃_{f-1},   a_f = v_f - v_{f-1}   (dt = 1 frame).
// A sample at t needs frames t-2 .. t+1, so 2 <= t <= T-2.
//
// Shapes (N garment vertices of all garments concatenated in layer order, P patches,
// B body vertices, K body neighbours, A attribute tokens, G garments):
//   state            (N, 12) [x̃_t, v_t, x̃_{t-1}, v_{t-1}]      raw
//   body_state       (B, 12) [x̃_{t+1}, v_{t+1}, x̃_t, v_t]      raw (the body at t+1 is an input)
//   patch_state      (P, 12) mean of member-vertex states          raw
//   *_norm           same shapes, (x - mean) / std per component: position stats on the
//                    x̃ columns, velocity stats on the v columns (official mean_std)
//   target           (N, 6)  [x̃_{t+1}, v_{t+1}]                 raw
//   target_patch_centre (P, 3) mean of member x̃_{t+1} (official loss_l2_patch target)
//   root_motion_norm (2, 6)  rows (t+1, t): [root velocity, root acceleration], normalised
//                    with the root_* statistics. Always present: with or without wind, the
//                    body's root motion reaches the model.
//   wind             (2, 5)  rows (t+1, t): [qw, qx, qy, qz, strength / 400]; only when the
//                    sequence has /wind (has_wind), else 0 rows. wind_rotation: R(q) per row.
//   gravity_norm     (2, 3)  rows (t+1, t): (g / fps - a_root - mean_acc) / std_acc (official
//                    quirk: g / fps, not g / fps^2; g from the file's `gravity` attribute)
//   attributes       (A, 5)  [(tension-15)/85, (bending-15)/185, (mass-0.2)/0.6,
//                    (self_friction-40)/40, (body_friction-40)/40]; identical rows merged
//                    (official), garment_attribute (G,) maps a garment to its row
//   world_edges      P rows: patches j with |c_i - c_j| < R at t, not mesh-adjacent
//   body_neighbours  (P, K) body vertices (at t+1) within R_b of the patch centres (at t)
//   vertex_nearest_body / patch_nearest_body: nearest body vertex (at t+1) of each garment
//                    vertex / patch centre (at t), with that vertex's normal (at t+1):
//                    vertex_body_normal (N, 3), patch_body_normal (P, 3)
//   structure        static per sequence (patches, adjacency, vertex/patch -> garment),
//                    built once and shared by every sample of the sequence
// Layer structure (has_layers) exists only with >= 2 garments: the last garment is the
// outer layer.
#include "dataset/body_skin.h"
#include "dataset/neighbours.h"
#include "dataset/patches.h"
#include "dataset/sequence.h"
#include "dataset/stats.h"

#include <Eigen/Core>

#include <array>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

namespace layersnet::dataset {

using RowMatrix = Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

inline constexpr float kWindStrengthRange = 400.f;  // official WIND_RANGE (0, 400)

// Static structure of one sequence's garments (frame-independent).
struct SequenceStructure {
  std::vector<PatchStructure> garments;   // per garment
  PatchStructure all;                     // concatenated (layer order)
  std::vector<int32_t> vertex_offsets;    // (G+1) first vertex of each garment
  std::vector<int32_t> patch_offsets;     // (G+1) first patch of each garment
  std::vector<int32_t> vertex_garment;    // (N,) garment of each vertex
  std::vector<int32_t> patch_garment;     // (P,) garment of each patch
  RowMatrix attributes;                   // (A, 5) normalised, deduplicated
  std::vector<int32_t> garment_attribute; // (G,)
  std::vector<std::string> garment_types; // (G,)
  // Mesh neighbours of each vertex (every garment edge, both ways) and that edge's rest length,
  // scene units: from the /rest template, else the UV length x scale (UVs are metres of rest cloth).
  Csr vertex_neighbours;                  // N rows, ascending
  std::vector<float> neighbour_rest;      // aligned with vertex_neighbours.items
  BodyTopology body;                      // the body mesh's vertex neighbours (body_skin.h)
  std::vector<int32_t> faces;             // (F·3) every garment's triangles, ids into the N vertices
  // Every garment edge once, and a hinge at every edge two faces share: the cloth's springs and
  // bending (losses/physics.h). Rest lengths (scene units) and angles come from the /rest
  // template in double; without one, from the edge's neighbour_rest, and the rest angle is flat.
  struct Edge {
    int32_t i, j, garment;  // i < j, global vertex ids
    double rest_length;
  };
  // Face A = (i, j, a) as wound, face B = (p, q, b) as wound, {p, q} = {i, j}; cos0 and sin0 of
  // the rest dihedral angle (sin about the unit i − j); rest_height the harmonic mean of the two
  // faces' rest heights over the edge (2 area / edge length, scene units).
  struct Hinge {
    int32_t i, j, a, p, q, b, garment;
    double rest_length, cos0, sin0, rest_height;
  };
  std::vector<Edge> edges;    // per garment, in ascending (i, j)
  std::vector<Hinge> hinges;  // in the order of their edges
  int num_vertices() const { return all.num_vertices; }
  int num_patches() const { return all.num_patches; }
};

struct SampleOptions {
  float patch_size = kDefaultPatchSize;
  NeighbourOptions neighbours;
  bool body_carry = false;       // fill TrainingSample::body_carry
  bool body_carry_prev = false;  // and TrainingSample::body_carry_prev
  int carry_smoothing = 0;       // smooth_over_mesh iterations on both carries (body_skin.h)
};

// Normalised attribute row of a garment in a sequence (official ATTR_RANGE).
Eigen::Matrix<float, 1, 5> normalised_attributes(const GarmentAttributes& g, float body_friction);

std::shared_ptr<const SequenceStructure> build_structure(const SequenceInfo& info, float patch_size);

// A hinge's rest height from its two faces' heights over the edge (scene units): their harmonic
// mean, 0 when either is 0 (a degenerate face).
double hinge_rest_height(double face_height_a, double face_height_b);

// A symmetric positive-definite matrix A of 3×3 blocks over the garment vertices (block CSR)
// and a scale s per vertex: y = A⁻¹ (s ⊙ b) moves the cloth as the physics step's last Newton
// system would (losses/physics_step.h). A pinned vertex has an identity block, no other block in
// its row or column, and scale 0.
template <class T>
struct BlockSystem {
  std::vector<int32_t> offsets;  // (N+1) CSR over block rows
  std::vector<int32_t> columns;  // (nnz) block column of each block
  std::vector<T> blocks;         // (nnz · 9) row-major 3×3 blocks
  std::vector<T> scale;          // (N) s
  bool empty() const { return offsets.empty(); }
};

struct TrainingSample {
  std::string sequence_id;
  int frame = 0;  // t
  std::shared_ptr<const SequenceStructure> structure;
  RowMatrix state, state_norm;            // (N, 12)
  RowMatrix body_state, body_state_norm;  // (B, 12)
  RowMatrix patch_state, patch_state_norm;  // (P, 12)
  RowMatrix target;                       // (N, 6)
  Points target_patch_centre;             // (P, 3)
  Eigen::Matrix<float, 2, 6, Eigen::RowMajor> root_motion_norm;
  Eigen::Vector3f root_translation = Eigen::Vector3f::Zero();       // r_t (world)
  Eigen::Vector3f root_translation_next = Eigen::Vector3f::Zero();  // r_{t+1} (world)
  bool has_wind = false;
  RowMatrix wind;                                 // (2, 5) or (0, 5)
  std::array<Eigen::Matrix3f, 2> wind_rotation{Eigen::Matrix3f::Identity(), Eigen::Matrix3f::Identity()};
  Eigen::Matrix<float, 2, 3, Eigen::RowMajor> gravity_norm;
  bool has_layers = false;
  Csr world_edges;
  BodyNeighbours body_neighbours;
  NearestBody vertex_nearest_body, patch_nearest_body;
  Points vertex_body_normal, patch_body_normal;   // (N, 3), (P, 3)
  Points body_normals_next;                       // (B, 3) at t+1
  // The displacement the body surface gives each x_t from t to t+1 (body_skin.h: bound at t,
  // carried to t+1), root-relative like v, then smoothed over the garment mesh
  // (options.carry_smoothing): units/frame.  (N, 3); empty unless options.body_carry.
  Points body_carry;
  // The same from t-1 to t (x_{t-1} bound at t-1, carried to t).  (N, 3); empty unless options.body_carry_prev.
  Points body_carry_prev;
  // One implicit step of Blender's cloth energy from x_t as a root-relative displacement
  // (losses/physics_step.h): units/frame.  (N, 3); empty unless the caller adds it.
  Points physics_step;
  // The step's linear system at its result, for a network correction that the step solves
  // (model.physics_step_correction = "solved"); empty unless the caller adds it.
  BlockSystem<float> physics_system;
  int num_vertices() const { return static_cast<int>(state.rows()); }
  int num_patches() const { return static_cast<int>(patch_state.rows()); }
};

// Builds one sample. `frames` must contain frames t-2 .. t+1 (2 <= t <= T-2).
TrainingSample build_sample(const SequenceInfo& info, const FrameWindow& frames, int t,
                            const NormalisationStats& stats, std::shared_ptr<const SequenceStructure> structure,
                            const SampleOptions& options = {});

// Cross-garment world edges: for each patch of the outer (last) garment, in its patch order,
// how many of its world edges reach a patch of an inner garment. Empty with one garment.
std::vector<int32_t> outer_to_inner_world_edges(const TrainingSample& sample);

// Which input frames t of a T-frame sequence give samples.
struct FrameSelection {
  int start_frame = 0;    // official 60
  int max_frames = -1;    // official 40; -1 = to the end
  int first_offset = 2;   // first t = start_frame + first_offset (>= 2); official 3
  static FrameSelection official() { return {60, 40, 3}; }
};
std::vector<int> sample_frames(int num_frames, const FrameSelection& selection);

// Caches the static structure per sequence id (thread-safe); the structure is computed
// once per garment set, not per sample. Holds at most max_entries sequences (oldest
// dropped first) so that memory stays bounded on large data sets.
class StructureCache {
 public:
  explicit StructureCache(float patch_size = kDefaultPatchSize, size_t max_entries = 256)
      : patch_size_(patch_size), max_entries_(max_entries) {}
  std::shared_ptr<const SequenceStructure> get(const std::string& sequence_id, const SequenceInfo& info);
  size_t size() const;
  int builds() const { return builds_; }

 private:
  float patch_size_;
  size_t max_entries_;
  mutable std::mutex mutex_;
  std::map<std::string, std::shared_ptr<const SequenceStructure>> cache_;
  std::vector<std::string> insertion_order_;
  int builds_ = 0;
};

}  // namespace layersnet::dataset
