#pragma once
// Per-frame evaluation metrics (the paper's; official losses/accuracy.py).
//
// Dimension letters: N garment vertices of all garments (layer order, concatenated),
// N_g of garment g, B body vertices. Positions are world coordinates in scene units.
//
//   Euclidean error   e_v = ‖x̂_v − x_v‖₂ per vertex; a frame's error is the mean over its
//                     vertices (all garments: Σ_v e_v / N, which equals the official
//                     vertex-weighted average of per-garment means Σ_g err_g·N_g / N).
//   H-collision       vertex x collides with the body when, for its nearest body vertex h
//                     (k-d tree, body of the same frame) with vertex normal n,
//                     (x − h)·n < 0 and ‖x − h‖ ≤ max_distance (official: 5.0 data units,
//                     i.e. 0.5 m at scale 10 — the far side of a limb is not "inside").
//                     Rate = colliding / N (all garment vertices).
//   L-collision       outer vertex x (last garment) collides when, for its nearest vertex y
//                     among all inner garments (same frame, same source: predicted for a
//                     prediction, ground truth for the floor) with that inner mesh's vertex
//                     normal n (normalised sum of unit face normals, dataset::
//                     vertex_normals), (x − y)·n < 0. No distance limit (official). A second
//                     count ("near") only counts outer vertices within max_layer_distance of
//                     y: farther away the nearest inner vertex says nothing about the side
//                     (a coat hem hanging between two trouser legs, a sleeve beyond a
//                     sleeveless inner garment) — the generator's quality gate uses the same
//                     limit (0.05 m), and the ground-truth floor shows how much it matters.
//                     Two denominators: rate_outer = colliding / N_outer (the share of
//                     outer-layer vertices; our headline number) and rate_all = colliding / N
//                     (what the official per-frame aggregate divides by, see
//                     model/README.md quirk 9).
// All comparisons are strict (< 0), no epsilon, as the official code. Non-finite rows (a
// diverged prediction) never count as collisions but stay in the denominators; the error
// of such a frame is NaN.
#include "dataset/garments.h"
#include "dataset/sequence.h"

#include <Eigen/Core>

#include <array>

#include <cstdint>
#include <vector>

namespace layersnet::eval {

using dataset::Faces;
using dataset::Points;

// Mean per-vertex L2 distance; pred, truth: (n, 3), same n > 0.
double mean_vertex_error(const Eigen::Ref<const Points>& pred, const Eigen::Ref<const Points>& truth);

// Number of garment vertices inside the body (see above). garments (N, 3), body (B, 3),
// body_faces (Fb, 3) counter-clockwise from outside. max_distance in scene units (< 0: none).
int64_t count_body_collisions(const Eigen::Ref<const Points>& garments, const Eigen::Ref<const Points>& body,
                              const Faces& body_faces, double max_distance);

// Number of outer vertices on the inner side of the nearest inner-layer vertex.
// outer (N_o, 3); inner: positions (N_i, 3) of all inner garments concatenated and their
// faces re-indexed into that concatenation (inner_faces (F_i, 3)).
// max_distance in scene units (< 0: no limit, the official rule).
int64_t count_layer_collisions(const Eigen::Ref<const Points>& outer, const Eigen::Ref<const Points>& inner,
                               const Faces& inner_faces, double max_distance = -1);

// The garment layout of a sequence, for splitting the concatenated positions.
using dataset::GarmentLayout;
using dataset::garment_layout;
using dataset::inner_faces;

// Everything one frame contributes (numerators and denominators, so sums stay exact).
struct FrameMetrics {
  double error = 0;                     // mean over all N vertices (scene units)
  std::vector<double> garment_error;    // (G,) mean over each garment's vertices
  double inner_error = 0;               // mean over the inner garments' vertices (all if G = 1)
  double outer_error = -1;              // mean over the outer garment (-1 when not layered)
  int64_t body_collisions = 0;          // H numerator; denominator N
  int64_t layer_collisions = 0;         // L numerator; denominators N_outer and N (-1 count if not layered)
  double h_rate = 0;                    // body_collisions / N
  double l_rate_outer = -1;             // layer_collisions / N_outer, -1 when not layered
  double l_rate_all = -1;               // layer_collisions / N (official aggregate)
  int64_t layer_collisions_near = 0;    // within max_layer_distance only (-1 if not layered)
  double l_rate_outer_near = -1;        // layer_collisions_near / N_outer
};

struct CollisionOptions {
  double max_body_distance = 5.0;   // scene units; official 5.0 (0.5 m at scale 10)
  double max_layer_distance = 0.5;  // scene units, "near" L-collision only (0.05 m at scale 10)
};

// Metrics of one frame. pred / truth (N, 3) world; body (B, 3) of the same frame.
// Collisions are those of `pred` (pass truth as pred for the ground-truth floor).
FrameMetrics frame_metrics(const GarmentLayout& layout, const Eigen::Ref<const Points>& pred,
                           const Eigen::Ref<const Points>& truth, const Eigen::Ref<const Points>& body,
                           const Faces& body_faces, const CollisionOptions& options = {});

// Crumple: the dihedral angle of every interior edge, the angle between the unit normals of
// the two triangles sharing it (0 = flat, 180 degrees = folded shut). Cloth that crumples into
// paper keeps its edge lengths, so edge strain cannot see it; this measure does.
struct FacePairs {
  std::vector<std::array<int32_t, 3>> first, second;  // (E,) the two triangles' corners, rows of x
};
// Every pair of triangles that share an edge, within each garment of `layout`, each pair once.
// Edges with more than two triangles (non-manifold) pair their first two.
FacePairs adjacent_face_pairs(const GarmentLayout& layout);
// Absolute dihedral angle of every pair, degrees; pairs with a degenerate or non-finite triangle
// are skipped. x (N, 3).
std::vector<double> dihedral_angles_deg(const FacePairs& pairs, const Eigen::Ref<const Points>& x);

// Mean and population standard deviation (ddof 0, as numpy's default) of values.
struct MeanStd {
  double mean = 0, std = 0;
  int64_t count = 0;
};
MeanStd mean_std(const std::vector<double>& values);

// q-quantile (q in [0, 1]) by linear interpolation between the sorted values (numpy's
// default percentile); 0 for no values. Values must not hold NaN.
double quantile(std::vector<double> values, double q);

}  // namespace layersnet::eval
