#pragma once
// A physics energy of one predicted frame, matched to the simulator that makes the ground truth:
// Blender's cloth, a mass-spring system integrated implicitly (docs/decisions.md, "Physics
// loss"). It needs no ground truth at t+1: it scores x̂_{t+1} given the state (x_t, x_{t−1}), the
// body at t+1, the wind and the garments' attributes, so it applies to every self-fed step.
//
// Units are Blender's own: positions in scene units (the data's `scale` × metres), time in
// frames (Blender's cloth step is time_scale / quality, and `quality` substeps make one frame),
// mass in the cloth's mass unit (`mass` attribute, per vertex). Energies are in
// mass · unit² / frame². One frame is one implicit step here (Blender takes `quality`, e.g. 30).
//
//   inertia    Σ_v m_v/2 ‖x_v − (2 x_t,v − x_{t−1},v)‖²               (Δt = 1 frame)
//   drag       Σ_v c/2 ‖x_v − x_t,v‖², c = air_damping × 0.01          (Blender's air drag −c·v,
//              as its backward-Euler potential)
//   stretch    Σ_e k_e/2 (‖x_i − x_j‖ − L_e)², k_e = tension_e / avg_spring_len, L_e the rest
//              length: one structural spring per mesh edge (a triangle mesh has no shear springs)
//   bending    Σ_h k_h (1 − cos(θ_h − θ0_h)) ≈ k_h/2 (θ_h − θ0_h)², θ the dihedral angle at an
//              interior edge, θ0 at rest, k_h = bending_h × L_h × 0.1 (Blender's angular model),
//              × the rest height h_h with PhysicsSettings::bending_by_height (Blender's force)
//   gravity    −Σ_v m_v g·(x_v − x_t,v), g = 0.001 × the file's gravity (Blender's factor)
//   wind       −Σ_v F_v·(x_v − x_t,v), F the face wind at x_t: each face gives its three corners
//              0.02 × area/3 × (w·n) n, w = strength × direction / fps (Blender's face wind;
//              PhysicsSettings::face_wind)
//   collision_body   k_c/2 Σ_v min((x_v − h_a)·n_a − d_b, 0)², a = nearest body vertex at t+1
//   collision_layer  k_c/2 Σ_v min((x_v − y_a)·n_a − d_l, 0)² over the outer garment's vertices,
//              y_a the nearest inner-garment vertex (predicted), n_a its predicted normal
//   friction   Σ_v μ m_v/2 ‖P_v (x_v − x0_v)‖² over the contacts add_contact_friction chose (none
//              unless it is called): x0 the body-carried start, P_v = I − n nᵀ at the body there
//
// Per-layer stiffness is what Blender simulated (SequenceInfo::stiffness_per_layer): each
// layer's stored value, or under the older generator rule (one cloth object, inner values as the
// base, the outer's as the maximum, group weight 1 on the outer layer) base + w·|max − base|.
// w = strength × the file's wind_field_factor × direction / fps. Pinned vertices (pin ≥ 0.5) carry no inertia, drag,
// gravity or wind (Blender moves them with the body); their springs stay.
// total = Σ weight_k · term_k / N (per garment vertex), weights from PhysicsSettings.
//
// Where each constant comes from in Blender's sources (3.x, the version the generator runs):
// spring stiffness scales and the bending factor 0.1 in cloth_calc_spring_force, gravity × 0.001
// and drag = air_damping × 0.01 in cloth_calc_force (simulation/intern/SIM_mass_spring.cpp);
// the linear spring force k(L − L0), the angular bending force k(θ − θ0) with θ from atan2 of
// the two face normals, and the face wind 0.02 · area/3 · (w·n) n in implicit_blender.c
// (3.x: calc_nor_area_tri returns the area; 2.8x returned twice it), w divided by the frame
// rate in effect.c (pd_point_from_loc sets vel_to_sec to it);
// dt = time_scale / quality per substep (blenkernel cloth.c); collision distances and their
// 8/9 push-out factor in blenkernel collision.c. Deviations: one step per frame instead of
// `quality`; compression uses the same quadratic as tension (Blender's angular model uses the
// Choi-Ko buckling curve for compression); 1 − cos(θ − θ0) stands for (θ − θ0)²/2 (equal to
// second order; no atan2 op is needed); collisions are vertex-to-nearest-vertex planes, not
// triangle pairs; contact friction is a tangential spring to where the body carries the vertex
// (Blender's is Coulomb friction inside its collision response); self-collision within a layer is
// not modelled.
#include "autodiff/tape.h"
#include "dataset/neighbours.h"
#include "dataset/sample.h"
#include "dataset/sequence.h"
#include "model/model_config.h"

#include <Eigen/Core>

#include <cstdint>
#include <memory>
#include <vector>

namespace layersnet::losses {

struct PhysicsSettings {
  // Weight of each term inside the energy (1 = as Blender; 0 = term absent, no op recorded).
  double inertia = 1, drag = 1, stretch = 1, bending = 1, gravity = 1, wind = 1, collision_body = 1,
         collision_layer = 1, friction = 1;
  double air_damping = 1.0;  // Blender's air_damping (Cvi), default 1; the generator keeps it
  // Collision target distances (scene units).
  double body_margin = kBlenderBodyMargin;
  double layer_margin = kBlenderLayerMargin;
  double collision_stiffness = 1e3;  // k_c (mass / frame²), the ramp's current value
  double face_wind = kBlenderFaceWind;  // per corner: face_wind · area / 3 · (w·n) n
  // k_h times the hinge's rest height h (SequenceStructure::Hinge::rest_height): Blender's angular
  // spring pushes a wing vertex with k_h (θ − θ0), where the energy's gradient pushes it with
  // k_h (θ − θ0) / h, 1/h times as hard (h is 0.23–0.48 units on the generator's garments).
  bool bending_by_height = false;
};

// Constants of one sample (N garment vertices, E edges, H interior edges, B body vertices).
// Positions are root-relative in frame t+1's coordinates (the predictions' frame).
template <class T>
struct PhysicsInput {
  std::vector<T> x_t, x_tm1;        // (N, 3) x_t and x_{t−1}, shifted by the root's motion to t+1
  std::vector<T> inertia_weight;    // (N, 1) m_v/2, 0 when pinned
  std::vector<T> drag_weight;       // (N, 1) c/2, 0 when pinned
  std::vector<T> external_force;    // (N, 3) m_v g, 0 when pinned
  std::vector<T> wind_force;        // (N, 3) F_v at x_t, 0 when pinned
  std::vector<int32_t> edge_i, edge_j;  // (E) structural springs
  std::vector<T> edge_rest;         // (E, 1) L_e
  std::vector<T> edge_half_k;       // (E, 1) k_e / 2
  // Interior edges: face A = (i, j, a) as wound, face B = (p, q, b) as wound, {p, q} = {i, j}.
  std::vector<int32_t> hinge_i, hinge_j, hinge_a, hinge_p, hinge_q, hinge_b;
  std::vector<T> hinge_k_cos0, hinge_k_sin0;  // (H, 1) k_h cos θ0, k_h sin θ0
  double hinge_k_sum = 0;                     // Σ k_h
  std::vector<int32_t> faces;                 // (F, 3) global vertex ids
  std::vector<int32_t> garment_offsets;       // (G + 1), inner -> outer
  std::vector<T> body_pos, body_normals;      // (B, 3) at t+1
  // Contact friction (add_contact_friction): the rows held, their start x0 and the body's unit
  // normal there ((F, 3) each), and μ m_v / 2 (F, 1).
  std::vector<int32_t> friction_rows;
  std::vector<T> friction_anchor, friction_normal, friction_half_weight;
  // A k-d tree over body_pos, for callers that evaluate many x against one body (a Newton
  // solve); null: body_collision_energy builds one per call.
  std::shared_ptr<const dataset::NearestVertexIndex> body_index;
  // Where the springs and hinges were read from (physics_input_from_sample; null when built by
  // hand): the physics step finds its Hessian's sparsity once per structure, not once per frame.
  std::shared_ptr<const dataset::SequenceStructure> structure;
};

// Rows [r0, r1) of an (R, 3) row-major array as float points (for the nearest-vertex queries).
template <class T>
dataset::Points rows_as_points(const T* xyz, int64_t r0, int64_t r1) {
  dataset::Points out(r1 - r0, 3);
  for (int64_t i = r0; i < r1; ++i)
    for (int c = 0; c < 3; ++c) out(i - r0, c) = static_cast<float>(xyz[3 * i + c]);
  return out;
}

// Sets in.body_index from in.body_pos.
template <class T>
void index_body(PhysicsInput<T>& in) {
  in.body_index = dataset::NearestVertexIndex::kept(
      rows_as_points(in.body_pos.data(), 0, static_cast<int64_t>(in.body_pos.size() / 3)));
}

// Body vertex a's stored normal n and the offset r = x − body_pos[a] of a point x from it.
struct BodyOffset {
  Eigen::Vector3d n, r;
};
template <class T>
BodyOffset offset_from_body(const PhysicsInput<T>& in, int32_t a, const Eigen::Vector3d& x) {
  const Eigen::Vector3d n(in.body_normals[3 * a], in.body_normals[3 * a + 1], in.body_normals[3 * a + 2]);
  return {n, x - Eigen::Vector3d(in.body_pos[3 * a], in.body_pos[3 * a + 1], in.body_pos[3 * a + 2])};
}

// Contact friction, as Blender's body friction holds cloth that touches the body: each vertex
// with mass (not pinned) whose start x0 (N, 3; the body-carried x_t + c, in the input's
// coordinates) lies within `distance` scene units of the body along its normal, its nearest body
// vertex within 2 · distance, pays μ m / 2 ‖P (x − x0)‖² for slipping tangentially (P = I − n nᵀ,
// n the body normal there). The contacts and normals are fixed, so the energy stays smooth.
// Replaces any contacts set before; μ = 0 or no body: none.
template <class T>
void add_contact_friction(PhysicsInput<T>& in, const dataset::Points& start, double mu, double distance);

// Builds the constants from a training sample (its state holds x_t, x_{t−1}, possibly the
// model's own, self-fed) and its sequence's static data (attributes, rest shapes, pins,
// translation, gravity, wind).
PhysicsInput<float> physics_input_from_sample(const dataset::TrainingSample& sample, const dataset::SequenceInfo& info,
                                              const PhysicsSettings& settings);

template <class U, class T>
PhysicsInput<U> cast_physics_input(const PhysicsInput<T>& in) {
  auto cv = [](const std::vector<T>& v) { return std::vector<U>(v.begin(), v.end()); };
  PhysicsInput<U> o;
  o.x_t = cv(in.x_t), o.x_tm1 = cv(in.x_tm1), o.inertia_weight = cv(in.inertia_weight);
  o.drag_weight = cv(in.drag_weight), o.external_force = cv(in.external_force), o.wind_force = cv(in.wind_force);
  o.edge_i = in.edge_i, o.edge_j = in.edge_j, o.edge_rest = cv(in.edge_rest), o.edge_half_k = cv(in.edge_half_k);
  o.hinge_i = in.hinge_i, o.hinge_j = in.hinge_j, o.hinge_a = in.hinge_a;
  o.hinge_p = in.hinge_p, o.hinge_q = in.hinge_q, o.hinge_b = in.hinge_b;
  o.hinge_k_cos0 = cv(in.hinge_k_cos0), o.hinge_k_sin0 = cv(in.hinge_k_sin0), o.hinge_k_sum = in.hinge_k_sum;
  o.faces = in.faces, o.garment_offsets = in.garment_offsets;
  o.body_pos = cv(in.body_pos), o.body_normals = cv(in.body_normals);
  o.friction_rows = in.friction_rows, o.friction_anchor = cv(in.friction_anchor);
  o.friction_normal = cv(in.friction_normal), o.friction_half_weight = cv(in.friction_half_weight);
  o.body_index = in.body_index;  // built from float positions either way
  o.structure = in.structure;
  return o;
}

// Unweighted values of each term (energy / N) and the weighted total on the tape.
template <class T>
struct PhysicsTerms {
  ad::Var<T> total;  // (1, 1) Σ weight_k term_k / N
  double inertia = 0, drag = 0, stretch = 0, bending = 0, gravity = 0, wind = 0, collision_body = 0,
         collision_layer = 0, friction = 0;
  int64_t body_contacts = 0, layer_contacts = 0;  // vertices inside a margin
  // (N) each row's nearest body vertex at x, as the body term found it (empty without that term):
  // the physics step's Hessian at the same x reuses it instead of querying again.
  std::vector<int32_t> body_nearest;
  // (N_outer) each outer vertex's nearest inner vertex at x and (N_outer · 3) that vertex's unit
  // normal, as the layer term found them (empty without that term): the step's Hessian reuses them.
  std::vector<int32_t> layer_nearest;
  std::vector<T> layer_normal;
};

// x: (N, 3) predicted positions at t+1 (root-relative, on the tape).
template <class T>
PhysicsTerms<T> physics_energy(ad::Tape<T>& tape, const ad::Var<T>& x, const PhysicsInput<T>& input,
                               const PhysicsSettings& settings);

// The single terms (each (1, 1), unweighted, not divided by N), for tests and the table above.
template <class T>
ad::Var<T> inertia_energy(ad::Tape<T>& tape, const ad::Var<T>& x, const PhysicsInput<T>& in);
template <class T>
ad::Var<T> drag_energy(ad::Tape<T>& tape, const ad::Var<T>& x, const PhysicsInput<T>& in);
template <class T>
ad::Var<T> stretch_energy(ad::Tape<T>& tape, const ad::Var<T>& x, const PhysicsInput<T>& in);
template <class T>
ad::Var<T> bending_energy(ad::Tape<T>& tape, const ad::Var<T>& x, const PhysicsInput<T>& in);
// −f·(x − x_t) summed, for the per-vertex force f (N, 3): gravity (external_force) or wind.
template <class T>
ad::Var<T> work_energy(ad::Tape<T>& tape, const ad::Var<T>& x, const PhysicsInput<T>& in, const std::vector<T>& force);
// `nearest`, when given, receives each row's nearest body vertex (N).
template <class T>
ad::Var<T> body_collision_energy(ad::Tape<T>& tape, const ad::Var<T>& x, const PhysicsInput<T>& in, double margin,
                                 double stiffness, int64_t* contacts = nullptr, std::vector<int32_t>* nearest = nullptr);
// `nearest` and `normal`, when given, receive each outer vertex's nearest inner vertex and its unit normal.
template <class T>
ad::Var<T> layer_collision_energy(ad::Tape<T>& tape, const ad::Var<T>& x, const PhysicsInput<T>& in, double margin,
                                  double stiffness, int64_t* contacts = nullptr, std::vector<int32_t>* nearest = nullptr,
                                  std::vector<T>* normal = nullptr);
template <class T>
ad::Var<T> friction_energy(ad::Tape<T>& tape, const ad::Var<T>& x, const PhysicsInput<T>& in);

// The HOOD-style schedule: `start` until step `ramp_start`, then linear to `end` over
// `ramp_steps` updates (0 = `end` at once after ramp_start).
double ramped(double start, double end, int64_t step, int64_t ramp_start, int64_t ramp_steps);

}  // namespace layersnet::losses
