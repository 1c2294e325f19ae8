#pragma once
// One implicit step of Blender's mass-spring cloth (the energy of losses/physics.h), the velocity
// base of model.velocity_base = "physics": a zero network output predicts where a few Newton
// iterations on that energy take the cloth from the body-carried guess x_t + c, so inertia, the
// springs, bending, gravity, the wind and the body's push are in every prediction, and the
// network learns what this coarse step misses (docs/decisions.md, "A physics step as the
// velocity base").
//
// Newton: the gradient comes from the tape; the Hessian is approximated by its mass and drag,
// the springs' PSD part k (d̂d̂ᵀ + max(0, 1 − L/l)(I − d̂d̂ᵀ)), bending's Gauss–Newton part
// k_h ∇θ ∇θᵀ and the body and layer contacts' k_c n nᵀ; conjugate gradients with a 3×3
// block-Jacobi preconditioner solve it, and a backtracking line search keeps the energy
// decreasing. Contact friction holds cloth that touches the body to the body's motion,
// tangentially, as Blender's body friction does (off in these settings; ModelConfig turns it on
// for the "physics" base). Pinned vertices (no inertia weight) stay where
// the guess puts them (PhysicsStepSettings::pins): Blender drives them, it does not simulate them. One frame is one step by default (Blender takes
// `quality` substeps, 30 in the generator; two or three here come no closer to it). Blender's frames are not minima of this energy (`layersnet inspect
// --physics`): a few iterations, not the minimum, are what comes closest to them.
//
// The inertia target is Blender's 2x_t − x_{t−1} ("world", the default), or the cloth's velocity
// relative to the body surface kept, x_t + c + (v_t − c_t) ("body": cloth in contact moves with
// the body as friction makes Blender's do; 3–4 % further from Blender over 36 frames).
// Deterministic: the same bits on any thread count (the conjugate gradients, the one part on
// threads, sum in fixed chunks of rows), double precision.
#include "dataset/sample.h"
#include "dataset/sequence.h"
#include "losses/physics.h"
#include "model/model_config.h"

#include <string>

namespace layersnet::losses {

struct PhysicsStepSettings {
  int newton_iterations = 2;   // per substep; 0 = the guess itself
  int substeps = 1;            // implicit steps of 1/substeps frame (Blender takes `quality`)
  int cg_iterations = 60;      // per Newton iteration (stops earlier at a relative residual of 1e-4)
  std::string inertia = "world";  // "world" | "body" (above)
  // Pinned rows at t+1: "carried" (x_t + c) or "recorded" (the sample's target rows, where the
  // sequence's simulator drove them; only when SequenceInfo::pins_recorded, else carried).
  std::string pins = "carried";
  // Contact friction: a free vertex that starts within friction_distance (scene units) of the
  // body along its normal pays (friction · m / 2) |tangential slip from x_t + c|²; 0 = none.
  double friction = 0;
  double friction_distance = 0.1;
  PhysicsSettings energy;      // Blender's constants; collision_stiffness is k_c of the step
};

struct PhysicsStepReport {
  double energy_start = 0, energy_end = 0;  // E at the guess and at the result (per vertex)
  int line_search_halvings = 0;             // over all iterations
};

// The step from x (N, 3) given `in` (x_t, x_{t−1} as the inertia target wants them), in the
// physics input's coordinates. `fixed` (N) marks rows that keep x's value. `system`, when given,
// receives the approximate Hessian at the result with the inertia weights as its scale
// (dataset::BlockSystem): A⁻¹ (s ⊙ a) is how the last Newton system would move the cloth if the
// inertia target moved by a (springs and bending resist what stretches and folds it).
dataset::Points minimise_step_energy(PhysicsInput<double> in, dataset::Points x, const std::vector<uint8_t>& fixed,
                                     const PhysicsStepSettings& settings, PhysicsStepReport* report = nullptr,
                                     dataset::BlockSystem<float>* system = nullptr);

// The sample's physics step as a root-relative displacement of x_t (units/frame, (N, 3)): what
// TrainingSample::physics_step holds. Needs sample.body_carry, and body_carry_prev for the
// "body" inertia.
// `system` as minimise_step_energy's (one step per frame only).
dataset::Points physics_step_displacement(const dataset::TrainingSample& sample, const dataset::SequenceInfo& info,
                                          const PhysicsStepSettings& settings, PhysicsStepReport* report = nullptr,
                                          dataset::BlockSystem<float>* system = nullptr);

// The step a model takes (Blender's constants, the model's iterations, inertia target, contact
// stiffness, layer term, friction and face wind coefficient).
PhysicsStepSettings physics_step_settings(const ModelConfig& model);

// Fills sample.physics_step with the step of physics_step_settings(model) when the model's
// velocity base is "physics", and sample.physics_system when the model solves its correction
// through the step (model.physics_step_correction = "solved"); any other base
// leaves the sample as it is. Every sample a model sees, in training and in a rollout, passes
// through here.
void add_physics_step(dataset::TrainingSample& sample, const dataset::SequenceInfo& info, const ModelConfig& model);

}  // namespace layersnet::losses
