#pragma once
// Sizes and switches of the LayersNet model. Defaults are the official implementation's
// (its model config, layersnet.py); configs/*.toml override them
// under [model]. Distances are in scene units (D-LAYERS: 10 units per metre).
#include <string>

namespace layersnet {

// Where Blender's collisions leave cloth (scene units): it pushes to 8/9 of its detection distance,
// (distance_min + the body's thickness_outer) for the body and 2 × self_distance_min for cloth;
// the generator sets 0.1 (+ 0.02 default thickness) and 0.06.
inline constexpr double kBlenderBodyMargin = (0.1 + 0.02) * 8.0 / 9.0;
inline constexpr double kBlenderLayerMargin = 2 * 0.06 * 8.0 / 9.0;
// Blender's face wind (3.x, the generator's version): each triangle of area A gives each corner
// kBlenderFaceWind · A / 3 · (w·n) n, w the field's wind vector over the frame rate. A pinned square
// stepped with it hangs and flaps as Blender's does (docs/decisions.md, "The face wind at half").
inline constexpr double kBlenderFaceWind = 0.02;

struct ModelConfig {
  int width = 128;                  // d: token channels
  int heads = 8;                    // H: attention heads (half world, half mesh)
  int layers = 4;                   // transformer layers of the simulator
  int ffn_width = 256;              // hidden width of each layer's FFN
  int decoder_width = 268;          // decoder MLP width (official: 12 + 2·128)
  double patch_size = 0.04;         // UV grid cell, UV units (metres of rest cloth)
  double world_radius = 0.4;        // R: patch-to-patch world edges
  double body_radius = 0.6;         // R_b: patch-to-body neighbours
  int body_neighbors = 16;          // K: body vertices per patch
  std::string body_query = "nearest";  // "nearest" K, or "first" K in index order (official ball query)
  int decoder_patch_candidates = 4;    // patches per vertex in the decoder
  // k: 3-vector channels the decoder's RET rotates, φ(R) = W (I_k ⊗ R) Wᵀ with W (d, 3k).
  // Official: 1, so the decoder sees only a 3-D projection of each token (rank 3); larger k
  // keeps the equivariance and lets more of the token through (model/README.md). 3k ≤ d.
  int decoder_ret_channels = 8;
  std::string attention = "ria";    // "ria" (paper eq. 5–7) or "tie" (TIE's LayerNorm logits)
  bool rotation_equivalent = true;  // RET (eq. 8–11); false = the "vanilla" ablation
  std::string orthogonality = "penalty";  // W_R: "penalty" (official) or "exact" (QR parametrisation)
  // Not in the paper: the decoder's vertex branch also sees the vertex's local features
  // (ModelInput::vertex_local: nearest body vertex motion, spring force, Laplacians), through
  // its own first-layer weight decoder.local.weight (decoder_width, 21).
  bool vertex_local_features = false;
  // What a zero network output predicts for the next frame (docs/decisions.md, "A velocity base
  // that follows the body"). "inertia" (official): v_{t+1} = v_t + a, the cloth keeps its
  // velocity. "body": v_{t+1} = c + a with c the displacement the body surface gives x_t from t to
  // t+1 (dataset/body_skin.h), so a zero output is the skinning baseline's step and the network
  // predicts how the cloth moves against the body. "body_inertia": v_{t+1} = c + (v_t − c_t) + a,
  // c_t the same displacement from t−1 to t: the cloth keeps its velocity relative to the body.
  // "physics": v_{t+1} = s + a with s one implicit step of Blender's cloth energy from x_t
  // (losses/physics_step.h, TrainingSample::physics_step), started at the body carry.
  std::string velocity_base = "inertia";
  // "physics" only: Newton iterations of the step; its inertia target ("body" keeps the cloth's
  // velocity relative to the body surface, "world" is Blender's 2x_t − x_{t−1}); the body
  // contact's stiffness k_c (mass / frame²); and whether the layer-contact term is in it.
  // Substeps split the frame into implicit steps of 1/substeps frame (iterations each).
  // Chosen on 36-frame zero-output rollouts on large val (docs/decisions.md, "A physics step as
  // the velocity base"): two iterations, not the minimum, one step per frame, Blender's inertia,
  // no layer term.
  int physics_step_iterations = 2;
  // Conjugate-gradient iterations per Newton iteration (fewer stop the linear solve short: a
  // speed-accuracy trade measured in docs/decisions.md, "Fewer conjugate-gradient iterations" and
  // "... on the softer step"). The one model key a rollout may change (run/config.h).
  int physics_step_cg_iterations = 60;
  int physics_step_substeps = 1;
  std::string physics_step_inertia = "world";
  // Where the step puts the pinned vertices at t+1. "carried": with the body surface under them,
  // as the rest of its guess (x_t + c). "recorded": where the sequence says its simulator drove
  // them (a generator's rig moves them with the torso's bones, which the body surface near them
  // does not follow); a scene without recorded pins falls back to the carry. Pinned vertices are
  // driven, not simulated, so they are the step's input like the body (docs/decisions.md,
  // "Recorded pins").
  std::string physics_step_pins = "carried";
  double physics_step_collision_stiffness = 1e4;
  bool physics_step_layer_collision = false;
  // Distance the layer term keeps the outer layer from the inner one (scene units).
  double physics_step_layer_margin = kBlenderLayerMargin;
  // The layer term's stiffness as a factor on physics_step_collision_stiffness: below 1 it pushes
  // a colliding outer vertex out over several frames instead of in one. At 0.01 (margin 0.005) the
  // large recipe's step alone is 2.3 % closer to Blender with half the layer collisions; at 1 it
  // is 1.5x further (docs/decisions.md, "A gentle layer term in the step").
  double physics_step_layer_stiffness = 1.0;
  // Contact friction of the step: a vertex within physics_step_friction_distance (scene units) of
  // the body along its normal is held to the body's tangential motion with stiffness friction × its
  // mass (losses/physics_step.h); 0 = frictionless contact. Chosen on the validation splits
  // (docs/decisions.md, "Contact friction in the physics step"): cloth inside the body's collision
  // margin (0.107 units) sticks to it, as Blender's body friction (48–80 in the data) holds it.
  double physics_step_friction = 4096;
  double physics_step_friction_distance = 0.1;
  // The step's face wind coefficient: twice Blender's. One step per frame moves garments less
  // with the wind than Blender's 30 substeps do, and on the 14 windy large val sequences the
  // step alone is closest to Blender at twice the coefficient (39.9 mm, against 41.2 at Blender's
  // own and 41.6 at four times; docs/decisions.md, "The face wind at half").
  double physics_step_face_wind = 2 * kBlenderFaceWind;
  // Factor on the step's bending stiffness, and whether each hinge's stiffness is scaled by its
  // rest height so that its force is Blender's (losses::PhysicsSettings::bending_by_height). On
  // large val the step alone is closest at 0.25 (45.8 mm against 48.8 at 1, 47.3 by the height;
  // docs/decisions.md, "The step's bending at a quarter"); 1 is the step the shipped models have.
  double physics_step_bending = 1.0;
  // Factor on the step's spring stiffness (k = tension / rest length). Half or twice it moves the
  // step 6–11 % further from Blender (docs/decisions.md, "The step's springs: the energy's own").
  double physics_step_stretch = 1.0;
  bool physics_step_bending_by_height = false;
  // How the network's correction a joins the step: "added" (x_{t+1} = x_t + s + a) or "solved":
  // a moves the step's inertia target and the step's last Newton system answers,
  // x_{t+1} = x_t + s + A⁻¹ (M a) (A the step's approximate Hessian at its result, M the masses;
  // TrainingSample::physics_system), so the springs and bending resist a correction that would
  // stretch or fold the cloth while a rigid one passes. One step per frame, no output_smoothing.
  // "added" on validation (docs/decisions.md, "The correction solved through the step").
  std::string physics_step_correction = "added";
  // "body_inertia" only: the share of the relative velocity v_t − c_t a zero output keeps,
  // v_{t+1} = c + swing_kept (v_t − c_t) + a. 1 keeps the whole swing, 0 is "body"; between them
  // the swing a self-fed rollout hands itself decays geometrically.
  double swing_kept = 1.0;
  // Jacobi averaging steps over the garment mesh applied to the body carry c (not "inertia"). The
  // carry binds each vertex to its nearest body vertex, so neighbours bound to different limbs
  // (a hem between the legs) move apart; averaging keeps them together (docs/decisions.md,
  // "A smoother carry"). 0 = the skinning step itself.
  int carry_smoothing = 0;
  // Jacobi averaging steps over the garment mesh applied to the network's per-vertex correction
  // (the prediction minus its velocity base), the same operator as carry_smoothing. Per-vertex
  // corrections that differ between neighbours stretch and crumple the cloth in long rollouts;
  // averaged, neighbours are corrected together. 0 = the official decoder output.
  int output_smoothing = 0;
  // With a carried velocity base (body, body_inertia or physics): each patch token also gets its
  // base, the patch mean c̄_p / σ_v (root-relative like v_t) of the body carry or of the physics
  // step, through embed.base.weight (width, 3), added to the patch embedding. The network corrects
  // the base without otherwise seeing it. The weight starts at zero, so a model with it starts as
  // the same model without it.
  bool patch_base_input = false;
  // With a carried velocity base: the decoder's vertex rows also see their own vertex's base,
  // c_v and c_v − c̄_p (p the row's patch), / σ_v in the row's frame, through decoder.base.weight
  // (decoder_width, 6), zero at the start. The patch token sees only its mean; this lets the
  // network correct the step vertex by vertex (near the body above all). Not in the paper.
  bool vertex_base_input = false;
  // The wind as Blender applies it: each garment vertex gets the face wind at x_t
  // (ModelInput::wind_force, dataset::face_wind_force), each patch its members' mean. The decoder
  // sees it in each row's frame through decoder.wind.weight (decoder_width, 3), the patch tokens
  // in world axes through embed.wind_force.weight (width, 3); both start at zero. Without it the
  // wind reaches the network only as one token that the attention may ignore. Not in the paper.
  bool wind_force_input = false;
};

struct LossConfig {
  double vertex = 1.0;           // λ_m, garment vertex position MSE (eq. 16)
  double patch = 1.0;            // patch-centre MSE
  double normal = 1.0;           // λ_n (eq. 17)
  double collision_body = 1.3;   // λ_b (eq. 18 against the ground-truth body)
  double collision_layer = 0.1;  // λ_g (eq. 18 outer vs inner layer; official: not × λ_b)
  double collision_eps = 0.001;  // d_ε, scene units
  // What the layer term's sum is divided by: "colliding", the outer vertices with a non-zero term
  // (eq. 18, official), or "outer", every outer vertex (not in the paper). Over the colliding ones
  // each vertex's push shrinks as more of them collide, so the term asks for shallow collisions,
  // not few; over every outer vertex each push is the same however many collide. Neither that nor
  // three times the weight lowered the large recipe's layer collisions (docs/decisions.md, "A
  // heavier layer loss, or one over every outer vertex").
  std::string layer_mean_over = "colliding";
  double orthogonality = 1.0;    // ||W Wᵀ − I||² + ||Wᵀ W − I||² penalty
  // Not in the paper (0 = off): mean over garment edges of ((|x̂_i − x̂_j| − l_ij) / l_ij)², l the
  // ground-truth length at t+1. Penalises the per-vertex jitter that crumples self-fed rollouts.
  double edge_strain = 0.0;
  // Not in the paper (false = off): the vertex and patch terms of each sample are divided by the
  // same error of its zero-output prediction (the velocity base from the sample's input state).
  // A self-fed chain's drifted step then counts as much as a one-step sample, instead of the
  // square of its larger error; the loss measures the gain over the base.
  bool relative_to_base = false;
  // Not in the paper (1 = as the paper): weight of the terms that compare with the ground-truth
  // cloth (vertex, patch, normal) on samples whose input is the model's own prediction. A drifted
  // chain's truth asks it to pull back towards the data, which the body carry already does;
  // below 1 the physics energy and the collision terms say more of how such a state moves on.
  double self_fed_truth = 1.0;
};

}  // namespace layersnet
