#include "train/sample_step.h"

#include "autodiff/ops_dense.h"
#include "losses/losses.h"
#include "losses/physics.h"
#include "losses/sample_loss_input.h"
#include "model/layersnet.h"
#include "model/sample_input.h"

#include <chrono>
#include <cmath>

namespace layersnet {

namespace {

double seconds_since(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

// The next input's garment state [x̃_{t+1}, v_{t+1}, x̃_t, v_t] (N, 12) on the tape: x̃_{t+1} the
// predicted positions (root-relative), the rest from this input's state (N, 12).
ad::Var<float> next_garment_state(ad::Tape<float>& tape, const model::Predictions<float>& pred,
                                  const ad::Var<float>& state) {
  const ad::Var<float> x = ad::slice_cols(tape, pred.vertex, 0, 3), x_before = ad::slice_cols(tape, state, 0, 3);
  return ad::concat_cols(tape, {x, ad::sub(tape, x, x_before), x_before, ad::slice_cols(tape, state, 3, 6)});
}

}  // namespace

LossParts& LossParts::operator+=(const LossParts& o) {
  total += o.total, vertex += o.vertex, patch += o.patch, normal += o.normal;
  collision_body += o.collision_body, collision_layer += o.collision_layer, orthogonality += o.orthogonality;
  edge_strain += o.edge_strain, physics += o.physics, physics_weighted += o.physics_weighted;
  return *this;
}

LossParts LossParts::scaled(double s) const {
  LossParts p = *this;
  p.total *= s, p.vertex *= s, p.patch *= s, p.normal *= s;
  p.collision_body *= s, p.collision_layer *= s, p.orthogonality *= s, p.edge_strain *= s;
  p.physics *= s, p.physics_weighted *= s;
  return p;
}

LossParts LossParts::weighted(const LossConfig& w) const {
  LossParts p = *this;
  p.vertex *= w.vertex, p.patch *= w.patch, p.normal *= w.normal, p.collision_body *= w.collision_body;
  p.collision_layer *= w.collision_layer, p.orthogonality *= w.orthogonality, p.edge_strain *= w.edge_strain;
  p.physics = p.physics_weighted;  // the weight is ramped per update: what it added is kept
  return p;
}

PhysicsStep physics_step_at(const PhysicsConfig& pc, int64_t update) {
  if (pc.weight <= 0) return {};
  return {losses::ramped(0.0, pc.weight, update, 0, pc.ramp_steps),
          losses::ramped(pc.collision_stiffness_start, pc.collision_stiffness_max, update, pc.collision_ramp_start,
                         pc.collision_ramp_steps)};
}

namespace {

losses::PhysicsSettings physics_settings(const PhysicsConfig& pc, double collision_stiffness) {
  losses::PhysicsSettings s;
  s.inertia = pc.inertia, s.drag = pc.drag, s.stretch = pc.stretch, s.bending = pc.bending, s.gravity = pc.gravity;
  s.wind = pc.wind, s.collision_body = pc.collision_body, s.collision_layer = pc.collision_layer, s.friction = pc.friction;
  s.air_damping = pc.air_damping, s.body_margin = pc.body_margin, s.layer_margin = pc.layer_margin;
  s.bending_by_height = pc.bending_by_height;
  s.collision_stiffness = collision_stiffness;
  return s;
}

}  // namespace

SampleOutcome train_sample(const TrainData& data, Window& window, int t, int self_fed, const Config& config,
                           ad::Tape<float>& tape, ad::ParamStore<float>& params, const PhysicsStep& physics) {
  using clock = std::chrono::steady_clock;
  SampleOutcome out;
  const int recorded = std::min(config.train.bptt_steps, self_fed);
  std::vector<float> predicted;
  auto build_input = [&](int f) {
    const auto start = clock::now();
    dataset::TrainingSample s = data.build(window, f);
    model::ModelInput<float> input = model::model_input_from_sample(s, data.stats(), config.model);
    out.build_seconds += seconds_since(start);
    return std::pair{std::move(s), std::move(input)};
  };
  // Self-fed steps before the recorded ones: inference only.
  for (int f = t - self_fed; f < t - recorded; ++f) {
    const auto [s, input] = build_input(f);
    const auto start = clock::now();
    tape.reset();
    {
      ad::NoRecord<float> off(tape);
      const auto x_next = model::next_positions(model::forward(tape, params, config.model, input));
      predicted.assign(x_next.data(), x_next.data() + x_next.size());
    }
    out.model_seconds += seconds_since(start);
    window.feed_back(f + 1, predicted.data());
  }
  tape.reset();
  params.zero_grads();
  // Recorded self-fed steps: each step's garment state is made on the tape from the step
  // before's prediction, so the loss's gradient flows back through them.
  // With train.bptt_score_every_step each of them is also scored against its own ground truth
  // (the window still holds it when the step's sample is built), and the loss is the mean.
  ad::Var<float> state;  // (N, 12) input state of the coming step; empty = a constant input
  ad::Var<float> step_losses;  // sum of the scored recorded steps' totals
  LossParts parts;
  int scored = 0;
  auto add_loss = [&](const losses::LossTerms<float>& terms) {
    step_losses = step_losses.value ? ad::add(tape, step_losses, terms.total) : terms.total;
    parts += {terms.total.scalar(), terms.vertex,          terms.patch,         terms.normal,
              terms.collision_body, terms.collision_layer, terms.orthogonality, terms.edge_strain};
    ++scored;
  };
  const bool score_physics = physics.weight > 0 && (self_fed > 0 || !config.physics.self_fed_only);
  // The step predicting from frame f has the model's own input when f > t − self_fed.
  LossConfig self_fed_loss = config.loss;
  self_fed_loss.vertex *= config.loss.self_fed_truth;
  self_fed_loss.patch *= config.loss.self_fed_truth;
  self_fed_loss.normal *= config.loss.self_fed_truth;
  auto loss_config_at = [&](int f) -> const LossConfig& { return f > t - self_fed ? self_fed_loss : config.loss; };
  for (int f = t - recorded; f < t; ++f) {
    const auto [s, input] = build_input(f);
    const auto start = clock::now();
    const auto pred = model::forward(tape, params, config.model, input, {}, state);
    if (config.train.bptt_score_every_step)
      add_loss(losses::compute_losses(tape, params, config.model, loss_config_at(f),
                                      losses::loss_input_from_sample(s, *window.info), pred));
    if (!state.value) state = tape.constant(input.state.data(), input.N, 12);
    state = next_garment_state(tape, pred, state);
    const auto x_next = model::next_positions(pred);
    predicted.assign(x_next.data(), x_next.data() + x_next.size());
    out.model_seconds += seconds_since(start);
    window.feed_back(f + 1, predicted.data());
  }
  window.add_input_noise(t);
  auto start = clock::now();
  const dataset::TrainingSample s = data.build(window, t);
  const model::ModelInput<float> input = model::model_input_from_sample(s, data.stats(), config.model);
  const losses::LossInput<float> target = losses::loss_input_from_sample(s, *window.info);
  out.build_seconds += seconds_since(start);
  start = clock::now();
  const auto pred = model::forward(tape, params, config.model, input, {}, state);
  losses::LossTerms<float> final_terms = losses::compute_losses(tape, params, config.model, loss_config_at(t), target, pred);
  if (score_physics) {
    // Beside the supervised loss: the energy of this prediction given its own (self-fed) state.
    const losses::PhysicsSettings settings = physics_settings(config.physics, physics.collision_stiffness);
    losses::PhysicsInput<float> physics_input = losses::physics_input_from_sample(s, *window.info, settings);
    if (config.physics.friction > 0) {
      // The step's contacts: where the body carries x_t (the sample's body carry, t+1's root frame).
      const dataset::Points start = s.state.leftCols<3>() + s.body_carry;
      losses::add_contact_friction(physics_input, start, config.model.physics_step_friction,
                                   config.model.physics_step_friction_distance);
    }
    const losses::PhysicsTerms<float> energy =
        losses::physics_energy(tape, ad::slice_cols(tape, pred.vertex, 0, 3), physics_input, settings);
    const ad::Var<float> added = ad::scale(tape, energy.total, static_cast<float>(physics.weight));
    final_terms.total = ad::add(tape, final_terms.total, added);
    parts.physics += energy.total.scalar();
    parts.physics_weighted += added.scalar();
  }
  add_loss(final_terms);
  const ad::Var<float> objective = scored > 1 ? ad::scale(tape, step_losses, 1.f / static_cast<float>(scored)) : step_losses;
  out.loss = parts.scaled(1.0 / scored);
  out.loss_finite = std::isfinite(objective.scalar());
  if (out.loss_finite) {
    tape.backward(objective);
    for (const float g : params.grads())
      if (!std::isfinite(g)) {
        out.grad_finite = false;
        break;
      }
  }
  tape.reset();
  out.model_seconds += seconds_since(start);
  return out;
}

namespace {

// Mean ‖x̂ − x‖ of a sample's prediction against its target; `predicted` receives x̂ (N·3,
// root-relative, row-major).
double predict_and_score(const TrainData& data, const Window& window, int t, const Config& config,
                         ad::Tape<float>& tape, ad::ParamStore<float>& params, std::vector<float>* predicted) {
  const dataset::TrainingSample s = data.build(window, t);
  const model::ModelInput<float> input = model::model_input_from_sample(s, data.stats(), config.model);
  tape.reset();
  ad::NoRecord<float> off(tape);
  const auto pred = model::forward(tape, params, config.model, input);
  double sum = 0;
  const auto x_next = model::next_positions(pred);
  if (predicted) predicted->assign(x_next.data(), x_next.data() + x_next.size());
  for (int64_t v = 0; v < x_next.rows(); ++v) {
    double d2 = 0;
    for (int c = 0; c < 3; ++c) {
      const float x = x_next(v, c);
      const double d = static_cast<double>(x) - s.target(v, c);
      d2 += d * d;
    }
    sum += std::sqrt(d2);
  }
  tape.reset();
  return x_next.rows() > 0 ? sum / static_cast<double>(x_next.rows()) : 0.0;
}

}  // namespace

double one_step_error(const TrainData& data, const Window& window, int t, const Config& config, ad::Tape<float>& tape,
                      ad::ParamStore<float>& params) {
  return predict_and_score(data, window, t, config, tape, params, nullptr);
}

double rollout_error(const TrainData& data, Window& window, int t0, int steps, const Config& config,
                     ad::Tape<float>& tape, ad::ParamStore<float>& params) {
  std::vector<float> predicted;
  double sum = 0;
  for (int f = t0; f < t0 + steps; ++f) {
    // Scored against frame f + 1 while the window still holds its truth, then fed back.
    sum += predict_and_score(data, window, f, config, tape, params, &predicted);
    window.feed_back(f + 1, predicted.data());
  }
  return steps > 0 ? sum / steps : 0.0;
}

}  // namespace layersnet
