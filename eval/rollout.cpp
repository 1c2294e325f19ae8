// Rollouts and predictors (see rollout.h).
#include "eval/rollout.h"

#include "dataset/garments.h"
#include "dataset/neighbours.h"

#include "eval/tether.h"

#include "losses/physics_step.h"
#include "model/layersnet.h"
#include "model/sample_input.h"
#include "run/checkpoint.h"
#include "run/run_dir.h"

#include <algorithm>
#include <chrono>
#include <limits>
#include <stdexcept>
#include <type_traits>

namespace layersnet::eval {

Points garments_at(const dataset::Sequence& seq, int t) { return dataset::garments_at(seq.info, seq.frames, t); }

Points rest_garments(const dataset::Sequence& seq) { return dataset::rest_shapes(seq.info, garments_at(seq, 0)); }

Points ConstantVelocity::step(const dataset::Sequence&, int, const Points&, const Points& x_prev,
                              const Points& x_now) {
  return 2.f * x_now - x_prev;
}

Points FollowBody::step(const dataset::Sequence& seq, int t, const Points&, const Points&, const Points& x_now) {
  const Eigen::RowVector3f shift = seq.info.translation.row(t + 1) - seq.info.translation.row(t);
  Points x = x_now;
  x.rowwise() += shift;
  return x;
}

void SkinnedToBody::begin(const dataset::Sequence& seq) {
  topology_ = dataset::body_topology(seq.info.body_faces, seq.info.num_body_vertices);
  binding_ = {};
}

Points SkinnedToBody::step(const dataset::Sequence& seq, int t, const Points&, const Points&, const Points& x_now) {
  if (topology_.neighbours.size() != static_cast<size_t>(seq.info.num_body_vertices)) begin(seq);
  auto frames_of = [&](const Points& body) {
    return rotate_ ? dataset::body_frames(body, seq.info.body_faces, topology_) : dataset::BodyFrames{};
  };
  if (binding_.points() != x_now.rows()) {
    const Points body = seq.body_at(t);
    binding_ = dataset::bind_to_body(x_now, body, frames_of(body), topology_, rotate_);
  }
  const Points body = seq.body_at(t + 1);
  return dataset::carry_with_body(binding_, body, frames_of(body));
}

PhysicsStep::PhysicsStep() : PhysicsStep(ModelConfig{}) {}

PhysicsStep::PhysicsStep(const ModelConfig& step_of) : model_(step_of) {
  model_.velocity_base = "physics";
  options_ = model::sample_options_for(model_);
}

void PhysicsStep::begin(const dataset::Sequence& seq) {
  structure_ = dataset::build_structure(seq.info, options_.patch_size);
}

Points PhysicsStep::step(const dataset::Sequence& seq, int t, const Points& x_prev2, const Points& x_prev,
                         const Points& x_now) {
  if (!structure_) begin(seq);
  const dataset::TrainingSample s =
      rollout_sample(seq, t, x_prev2, x_prev, x_now, dataset::NormalisationStats{}, structure_, options_, model_);
  Points x = s.state.leftCols<3>() + s.physics_step;  // root-relative at t+1
  x.rowwise() += s.root_translation_next.transpose();
  return x;
}

std::unique_ptr<const ClothConstraints> make_cloth_constraints(const dataset::Sequence& seq,
                                                               const EvalConfig& settings) {
  return std::make_unique<const ClothConstraints>(seq.info, rest_garments(seq), seq.body_at(0), garments_at(seq, 0),
                                                  settings);
}

void PostProcessed::begin(const dataset::Sequence& seq) {
  inner_->begin(seq);
  constraints_ = make_cloth_constraints(seq, settings_);
}

// The data's garments at t+1 when the settings take recorded pins and the sequence records
// them (the constraints put the pinned rows there); else empty.
Points recorded_pins_next(const dataset::Sequence& seq, int t, const EvalConfig& settings) {
  return settings.recorded_pins && seq.info.pins_recorded ? garments_at(seq, t + 1) : Points();
}

void apply_constraints(const ClothConstraints& constraints, const EvalConfig& settings, const dataset::Sequence& seq, int t,
                       Points& x, const Points& x_now) {
  const Points pins = recorded_pins_next(seq, t, settings);
  constraints.apply(seq.body_at(t + 1), x, seq.body_at(t), x_now, pins.rows() ? &pins : nullptr);
}

Points PostProcessed::step(const dataset::Sequence& seq, int t, const Points& x_prev2, const Points& x_prev,
                           const Points& x_now) {
  if (!constraints_) begin(seq);
  Points x = inner_->step(seq, t, x_prev2, x_prev, x_now);
  apply_constraints(*constraints_, settings_, seq, t, x, x_now);
  return x;
}

template <class T>
NetworkPredictor<T>::NetworkPredictor(Config config, ad::ParamStore<T> params, dataset::NormalisationStats stats)
    : config_(std::move(config)),
      params_(std::move(params)),
      stats_(std::move(stats)),
      sample_options_(model::sample_options_for(config_.model)) {}

ModelPredictor::ModelPredictor(std::string name, Config config, ad::ParamStore<float> params,
                               dataset::NormalisationStats stats)
    : NetworkPredictor<float>(std::move(config), std::move(params), std::move(stats)), name_(std::move(name)) {}

dataset::TrainingSample rollout_sample(const dataset::Sequence& seq, int t, const Points& x_prev2, const Points& x_prev,
                                       const Points& x_now, const dataset::NormalisationStats& stats,
                                       const std::shared_ptr<const dataset::SequenceStructure>& structure,
                                       const dataset::SampleOptions& options, const ModelConfig& model) {
  const dataset::SequenceInfo& info = seq.info;
  // The window t-2..t+1: body from the data, garments from the rollout (t+1 is only the
  // sample's unused target, so the ground truth fills it).
  dataset::FrameWindow w;
  w.first = t - 2;
  w.count = 4;
  const int B = info.num_body_vertices;
  w.body = seq.frames.body.middleRows(static_cast<Eigen::Index>(t - 2) * B, 4 * static_cast<Eigen::Index>(B));
  const Points* hist[3] = {&x_prev2, &x_prev, &x_now};
  Eigen::Index offset = 0;
  for (int g = 0; g < info.num_garments(); ++g) {
    const int n = info.garments[g].num_vertices;
    Points x(4 * static_cast<Eigen::Index>(n), 3);
    for (int k = 0; k < 3; ++k) x.middleRows(k * n, n) = hist[k]->middleRows(offset, n);
    x.middleRows(3 * n, n) = seq.garment_at(g, t + 1);
    w.garments.push_back(std::move(x));
    offset += n;
  }
  dataset::TrainingSample sample = dataset::build_sample(info, w, t, stats, structure, options);
  losses::add_physics_step(sample, info, model);
  return sample;
}

template <class T>
void NetworkPredictor<T>::begin(const dataset::Sequence& seq) {
  structure_ = dataset::build_structure(seq.info, sample_options_.patch_size);
  tether_limit_.clear();
  if (config_.eval.patch_tether > 0) tether_limit_ = tether_limits(seq, *structure_, config_.eval.patch_tether);
  constraints_.reset();
  if (config_.eval.constraints) constraints_ = make_cloth_constraints(seq, config_.eval);
  mirrored_.reset();
  mirrored_structure_.reset();
  if (config_.eval.mirror_average) {
    auto image = std::make_unique<dataset::Sequence>(seq);
    dataset::mirror(*image);
    mirrored_structure_ = dataset::build_structure(image->info, sample_options_.patch_size);
    mirrored_ = std::move(image);
  }
}

template <class T>
void NetworkPredictor<T>::apply_eval_settings(const std::vector<std::string>& assignments) {
  for (const auto& a : assignments) apply_rollout_override(config_, a);
  structure_.reset();
}

template <class T>
Points NetworkPredictor<T>::step(const dataset::Sequence& seq, int t, const Points& x_prev2, const Points& x_prev,
                                 const Points& x_now) {
  if (!structure_) begin(seq);
  const dataset::TrainingSample sample =
      rollout_sample(seq, t, x_prev2, x_prev, x_now, stats_, structure_, sample_options_, config_.model);
  Points x = predict_positions(tape_, params_, config_, sample, stats_);
  if (mirrored_) {
    const auto image = [](Points p) {
      dataset::mirror_points(p);
      return p;
    };
    const dataset::TrainingSample mirrored_sample = rollout_sample(*mirrored_, t, image(x_prev2), image(x_prev), image(x_now),
                                                                   stats_, mirrored_structure_, sample_options_, config_.model);
    x = 0.5f * (x + image(predict_positions(tape_, params_, config_, mirrored_sample, stats_)));
  }
  if (!tether_limit_.empty()) apply_tether(structure_->all, tether_limit_, x);
  if (constraints_) apply_constraints(*constraints_, config_.eval, seq, t, x, x_now);
  return x;
}

template <class T>
Points predict_positions(ad::Tape<T>& tape, ad::ParamStore<T>& params, const Config& config,
                         const dataset::TrainingSample& sample, const dataset::NormalisationStats& stats) {
  model::ModelInput<float> input = model::model_input_from_sample(sample, stats, config.model);
  tape.reset();
  ad::NoRecord<T> off(tape);
  model::ForwardOptions options;
  options.correction_scale = config.eval.correction_scale;
  model::Predictions<T> pred;
  if constexpr (std::is_same_v<T, float>)
    pred = model::forward(tape, params, config.model, input, options);  // no copy on the float rollout path
  else
    pred = model::forward(tape, params, config.model, model::cast_input<T>(input), options);
  Points x = model::next_positions(pred).template cast<float>();
  x.rowwise() += sample.root_translation_next.transpose();
  return x;
}
template Points predict_positions(ad::Tape<float>&, ad::ParamStore<float>&, const Config&, const dataset::TrainingSample&,
                                  const dataset::NormalisationStats&);
template Points predict_positions(ad::Tape<double>&, ad::ParamStore<double>&, const Config&,
                                  const dataset::TrainingSample&, const dataset::NormalisationStats&);

std::unique_ptr<ModelPredictor> load_model_predictor(const std::string& path, const std::string& name,
                                                     const dataset::NormalisationStats* fallback_stats) {
  LoadedModel m = load_model(path);
  dataset::NormalisationStats stats;
  if (!m.checkpoint.stats.empty()) {
    stats = stats_from_arrays(m.checkpoint.stats, path);
  } else {
    if (!fallback_stats)
      throw std::runtime_error(path + ": the checkpoint holds no normalisation statistics (/stats/position.mean ...) "
                               "and no data set stats.h5 was given; run `layersnet prepare <dataset>`");
    stats = *fallback_stats;
  }
  return std::make_unique<ModelPredictor>(name, std::move(m.config), std::move(m.params), std::move(stats));
}

Rollout rollout(Predictor& predictor, const dataset::Sequence& seq, int t0, int n, bool recorded_pins) {
  const int T = seq.info.num_frames;
  if (t0 < 2 || t0 + 1 > T - 1)
    throw std::invalid_argument(seq.info.path + ": a rollout from input frame " + std::to_string(t0) +
                                " needs 2 <= t0 <= T-2 (T = " + std::to_string(T) + ")");
  n = std::min(n, T - 1 - t0);
  if (n < 1) throw std::invalid_argument(seq.info.path + ": rollout length must be >= 1");
  Rollout r;
  r.first_frame = t0 + 1;
  predictor.begin(seq);
  Points a = garments_at(seq, t0 - 2), b = garments_at(seq, t0 - 1), c = garments_at(seq, t0);
  // Rows taken from the data every frame.
  const std::vector<Eigen::Index> driven =
      recorded_pins && seq.info.pins_recorded ? seq.info.pinned_rows() : std::vector<Eigen::Index>{};
  for (int k = 0; k < n; ++k) {
    const int t = t0 + k;
    if (r.diverged_at >= 0) {  // nothing sensible to feed back
      r.frames.push_back(Points::Constant(c.rows(), 3, std::numeric_limits<float>::quiet_NaN()));
      r.step_ms.push_back(0);
      continue;
    }
    const auto start = std::chrono::steady_clock::now();
    Points next = predictor.step(seq, t, a, b, c);
    r.step_ms.push_back(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count());
    if (next.rows() != c.rows())
      throw std::runtime_error(predictor.name() + " returned " + std::to_string(next.rows()) + " rows for " +
                               std::to_string(c.rows()) + " garment vertices");
    if (!driven.empty()) {
      const Points recorded = garments_at(seq, t + 1);
      for (const Eigen::Index v : driven) next.row(v) = recorded.row(v);
    }
    if (!next.allFinite()) r.diverged_at = k;
    r.frames.push_back(next);
    a = std::move(b);
    b = std::move(c);
    c = std::move(next);
  }
  return r;
}

template class NetworkPredictor<float>;
template class NetworkPredictor<double>;

}  // namespace layersnet::eval
