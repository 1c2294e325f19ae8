#pragma once
// Cloth constraints on each predicted frame of a rollout: an edge-length limit, a fold limit,
// and a collision shell outside the body and between the layers, projected as in
// position-based dynamics.
//
// After the network predicts x_{t+1} (world, scene units), each of `iterations` passes
//   1. brings every garment edge back within [1 − s, 1 + s] × its rest length (Gauss–Seidel
//      over the edges in a fixed order, both ends moved equally), s = strain_limit;
//   2. keeps every pair of triangles sharing an edge from folding shut: the distance of their
//      two far corners stays at least (1 − f) × its rest value, f = fold_limit (one-sided:
//      unfolding is free);
//   3. moves every garment vertex x whose nearest body vertex h (body of frame t+1, vertex
//      normal n) lies within `reach` and (x − h)·n < shell along n onto (x − h)·n = shell;
//   4. does the same for every outer-layer vertex against the nearest inner-layer vertex and
//      the inner mesh's normal there.
// The collision steps come last, so a frame ends outside the body and the inner layer. The passes
// stop after one that moves nothing: it left x as it found it, and so would the rest.
// Before the passes, when the frame before is given and eval.pins is set, pins: the vertices the
// file pins (a waistband, a top edge; GarmentMesh::pinned) move rigidly with the body under
// them, x_{t+1} = R x_t + c, where (R, c) is the least-squares rigid motion of that body region
// (the body vertices inside the loop the pinned vertices draw, in frame 0: dataset/pin_carry.h)
// from frame t to t+1.
// The data's simulator skins pinned cloth to the torso bones, so a free network prediction of
// them is wasted; no later step moves them (inverse mass 0 in the edge and fold steps; the
// friction and collision steps skip them). When the caller gives the pinned rows' recorded
// positions (eval.recorded_pins), they are put there instead of carried.
// Then, when body_friction μ > 0, contact friction:
//   0. every garment vertex whose nearest body vertex h (frame t+1) lies within `reach` and
//      (x − h)·n < friction_distance loses μ of its displacement relative to h's, tangentially:
//      x −= μ (r − (r·n) n), r = (x − x_t) − (h − h_t). Blender's cloth touching the body moves
//      with it (docs/decisions.md, "Contact friction"); the network alone lets it slide.
// Why: the network's vertex branch integrates each vertex's offset from its patch, and in a
// self-fed rollout these offsets drift frame by frame into stretched, crumpled cloth that sinks
// into the body and the layer below (docs/decisions.md, "Cloth constraints"); real cloth
// barely stretches and stays outside. Only positions change: the next step's velocities are
// differences of positions, so a projected frame also feeds back consistent velocities.
// Deterministic for any thread count (sequential passes).
#include "dataset/pin_carry.h"
#include "dataset/sequence.h"
#include "run/config.h"

#include <cstdint>
#include <utility>
#include <vector>

namespace layersnet {

// What one apply() moved.
struct ConstraintMoves {
  int64_t edges = 0;         // edge corrections (over all passes)
  int64_t folds = 0;         // far-corner corrections (over all passes)
  int64_t body = 0;          // vertices pushed out of the body (over all passes)
  int64_t layer = 0;         // outer vertices pushed out of the inner layer (over all passes)
  int64_t friction = 0;      // vertices the contact friction moved
  int64_t pinned = 0;        // pinned vertices carried with the body
  int32_t passes = 0;        // passes run: they stop after the first that moves nothing
};

// The two far corners (local indices) of every pair of triangles sharing an edge, each pair once.
std::vector<std::pair<int32_t, int32_t>> far_corners(const dataset::Faces& faces);

class ClothConstraints {
 public:
  // Edges and rest lengths from the garments of `info` and their rest shapes `rest` (N, 3;
  // dataset::rest_shapes). The body under each garment's pinned vertices is chosen in one frame
  // (frame 0): its body `body_first` (B, 3) and garments `garments_first` (N, 3). Settings:
  // eval.strain_limit (s; 0 = no edge step), fold_limit (f; 0 = no fold step), collision_shell
  // (scene units; 0 = no collision steps), constraint_iterations, pins; eval.constraints is
  // not read.
  ClothConstraints(const dataset::SequenceInfo& info, const dataset::Points& rest,
                   const Eigen::Ref<const dataset::Points>& body_first,
                   const Eigen::Ref<const dataset::Points>& garments_first, const EvalConfig& settings);
  // Projects x (N, 3, world, layer order) in place against the body of frame t (B, 3). A frame
  // with a non-finite value is left as it is (the rollout reports the divergence).
  ConstraintMoves apply(const Eigen::Ref<const dataset::Points>& body, dataset::Points& x) const;
  // The same with the frame before (body_before (B, 3), x_before (N, 3), world), which the pins
  // and the contact friction need; without it there is neither step. pins_next (N, 3), when
  // given: where the pinned rows are at this frame (recorded pins, eval.recorded_pins), taken
  // instead of the rigid carry.
  ConstraintMoves apply(const Eigen::Ref<const dataset::Points>& body, dataset::Points& x,
                        const Eigen::Ref<const dataset::Points>& body_before,
                        const Eigen::Ref<const dataset::Points>& x_before, const dataset::Points* pins_next = nullptr) const;

 private:
  ConstraintMoves project(const Eigen::Ref<const dataset::Points>& body, dataset::Points& x,
                          const Eigen::Ref<const dataset::Points>* body_before, const Eigen::Ref<const dataset::Points>* x_before,
                          const dataset::Points* pins_next) const;
  EvalConfig settings_;
  float reach_ = 0;                                 // scene units
  std::vector<std::pair<int32_t, int32_t>> edges_;  // rows of x
  std::vector<float> rest_;                         // (E,) scene units, > 0
  std::vector<std::pair<int32_t, int32_t>> folds_;  // far corners of triangle pairs, rows of x
  std::vector<float> fold_rest_;                    // (Q,) scene units, > 0
  dataset::Faces body_faces_;
  int32_t outer_begin_ = 0;                         // first outer-layer row; N when not layered
  dataset::Faces inner_faces_;                      // inner garments' faces, rows [0, outer_begin_)
  std::vector<uint8_t> pinned_;                     // (N,) 1 = pinned (eval.pins only): no other step moves it
  std::vector<dataset::PinGroup> pin_groups_;       // one per garment with pinned vertices
};

}  // namespace layersnet
