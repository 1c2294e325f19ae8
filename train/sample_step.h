#pragma once
// One sample of the paper's noisy-rollout curriculum (official EncoderDecoder.
// forward_train), and the one-step validation error.
//
// Curriculum. The official loop draws k ~ U{0..ngs}, runs ngs steps without gradient of
// which steps 0..k-1 take the ground-truth state (their predictions are dropped) and steps
// k..ngs-1 feed the model's own prediction back, then one step with gradient. Steps before
// k influence nothing, so we skip them: with T_n = ngs − k self-fed steps the rollout
// starts from ground truth at t − T_n, feeds back T_n predictions (positions; velocities
// and history follow from them) and takes the recorded step at t. Body, wind and gravity
// always come from the ground truth. With train.rollout_constraints every fed-back frame is
// first projected onto the cloth constraints (Window::feed_back), as rollouts do with
// eval.constraints.
#include "autodiff/params.h"
#include "autodiff/tape.h"
#include "run/config.h"
#include "train/train_data.h"

namespace layersnet {

struct LossParts {
  double total = 0, vertex = 0, patch = 0, normal = 0, collision_body = 0, collision_layer = 0, orthogonality = 0,
         edge_strain = 0;
  // The physics energy per garment vertex (losses/physics.h) and what it added to total (× its
  // ramped weight); 0 on samples it does not score.
  double physics = 0, physics_weighted = 0;
  LossParts& operator+=(const LossParts& o);
  LossParts scaled(double s) const;
  // Each term times its weight in `weights`: what it adds to total (total itself unchanged).
  LossParts weighted(const LossConfig& weights) const;
};

struct SampleOutcome {
  bool loss_finite = true;
  bool grad_finite = true;
  LossParts loss;
  double build_seconds = 0;  // building samples (neighbour search, normalisation) — outside the model
  double model_seconds = 0;  // forward + losses + backward
};

// Runs the self-fed rollout (T_n = self_fed steps from t − self_fed), then the loss step at t
// on that state plus window.input_noise: params.grads() is zeroed and receives d loss / d params.
// The last min(train.bptt_steps, self_fed) self-fed steps are recorded, and the gradient also
// flows through their predictions into the loss step's input (backpropagation through time);
// with train.bptt_score_every_step the loss is the mean of theirs and the final step's. The
// earlier ones run without recording. `window` must hold frames t − self_fed − 2 .. t + 1;
// its garment frames are overwritten.
// The physics energy's schedule at one update: its weight (0 = off) and collision stiffness.
struct PhysicsStep {
  double weight = 0;
  double collision_stiffness = 0;
};
// physics.weight ramped linearly over physics.ramp_steps, k_c ramped from start to max (HOOD's
// schedule); `update` counts the optimizer steps taken before this one.
PhysicsStep physics_step_at(const PhysicsConfig& physics, int64_t update);

// With physics.weight > 0 the loss step also scores the physics energy of its prediction
// (weight × energy per vertex, on self-fed samples only unless physics.self_fed_only is off).
SampleOutcome train_sample(const TrainData& data, Window& window, int t, int self_fed, const Config& config,
                           ad::Tape<float>& tape, ad::ParamStore<float>& params, const PhysicsStep& physics = {});

// Mean per-vertex Euclidean error ‖x̂_{t+1} − x_{t+1}‖ (scene units) of one step from the
// ground-truth state at t, without recording (params are only read).
double one_step_error(const TrainData& data, const Window& window, int t, const Config& config, ad::Tape<float>& tape,
                      ad::ParamStore<float>& params);

// Mean per-vertex Euclidean error (scene units) over a self-fed rollout of `steps` steps from
// the ground-truth state at t0: each step's prediction is compared with the truth at its
// frame, then fed back. `window` must hold frames t0 − 2 .. t0 + steps; its garment frames
// are overwritten.
double rollout_error(const TrainData& data, Window& window, int t0, int steps, const Config& config,
                     ad::Tape<float>& tape, ad::ParamStore<float>& params);

}  // namespace layersnet
