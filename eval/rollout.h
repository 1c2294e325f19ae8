#pragma once
// Autoregressive rollouts and the predictors that drive them.
//
// A rollout of sequence S from input frame t0 for n frames predicts frames t0+1 .. t0+n.
// It starts from the ground truth at frames t0-2, t0-1, t0 (the model's state needs x_t, v_t,
// x_{t-1}, v_{t-1}); every later garment state is the predictor's own output, while the body,
// its root translation and the wind come from the data at every frame (official
// single_gpu_rollout). The model runs without recording (ad::NoRecord).
//
// Positions: world coordinates, scene units; garments concatenated in layer order (N, 3).
#include "autodiff/params.h"
#include "autodiff/tape.h"
#include "run/cloth_constraints.h"
#include "dataset/body_skin.h"
#include "dataset/sample.h"
#include "dataset/sequence.h"
#include "dataset/stats.h"
#include "run/config.h"

#include <map>
#include <memory>
#include <string>
#include <vector>

namespace layersnet::eval {

using dataset::Points;

// Garment positions of frame t concatenated in layer order: (N, 3), world.
Points garments_at(const dataset::Sequence& seq, int t);
// Rest shapes (the file's /garments/<name>/rest; frame 0 for a garment without one), (N, 3).
Points rest_garments(const dataset::Sequence& seq);

// Predicts x_{t+1} (world, (N, 3)) from the three latest garment frames and the data.
class Predictor {
 public:
  virtual ~Predictor() = default;
  virtual std::string name() const = 0;
  // Called once per sequence before its first step.
  virtual void begin(const dataset::Sequence& /*seq*/) {}
  // True for the models under test: eval's --wind-scale changes the wind they are given; every
  // baseline keeps the data's.
  virtual bool takes_scaled_wind() const { return false; }
  // x_prev2, x_prev, x_now: garment positions at t-2, t-1, t (world, (N, 3)).
  virtual Points step(const dataset::Sequence& seq, int t, const Points& x_prev2, const Points& x_prev,
                      const Points& x_now) = 0;
};

// Baseline: x_{t+1} = 2 x_t − x_{t−1} (constant velocity in world space).
class ConstantVelocity : public Predictor {
 public:
  std::string name() const override { return "constant velocity"; }
  Points step(const dataset::Sequence& seq, int t, const Points& x_prev2, const Points& x_prev,
              const Points& x_now) override;
};

// Baseline: the garment carried rigidly with the body's root motion,
// x_{t+1} = x_t + (r_{t+1} − r_t) with r the body root translation (/body/translation;
// a file without it has r = 0 and the garment then stays where it is).
class FollowBody : public Predictor {
 public:
  std::string name() const override { return "follow the body"; }
  Points step(const dataset::Sequence& seq, int t, const Points& x_prev2, const Points& x_prev,
              const Points& x_now) override;
};


// Baseline: every garment vertex skinned to the body surface at the rollout's first input frame
// t0 and carried with it. The vertex is bound to its nearest body vertex and that vertex's mesh
// neighbours (weights ∝ 1 / squared distance); for each, its offset is kept in the body vertex's
// local frame (vertex normal, and a tangent towards a fixed neighbour), so the garment moves
// with the surface's translation and rotation: x_{t+1} = Σ w_i (h_i + F_i d_i) at frame t+1
// (dataset/body_skin.h). A body moved rigidly carries a bound garment exactly. With rotate = false the offsets stay in
// world axes (each vertex follows its body vertices' translation only). The rollout's own
// state is not fed back: the binding is made once, from the ground truth at t0.
class SkinnedToBody : public Predictor {
 public:
  explicit SkinnedToBody(bool rotate = true) : rotate_(rotate) {}
  std::string name() const override { return rotate_ ? "skinned to the body" : "nearest body vertices (translation)"; }
  void begin(const dataset::Sequence& seq) override;
  Points step(const dataset::Sequence& seq, int t, const Points& x_prev2, const Points& x_prev,
              const Points& x_now) override;

 private:
  bool rotate_;
  dataset::BodyTopology topology_;
  dataset::SkinBinding binding_;  // empty until the first step
};

// Baseline: one implicit step of Blender's cloth energy per frame, no network
// (losses/physics_step.h): what a model with model.velocity_base = "physics" predicts when its
// output is zero, fed its own frames. Built from such a model's config it is that model's own
// step (its physics_step_* keys); by default, the step with every key at its default.
class PhysicsStep : public Predictor {
 public:
  PhysicsStep();
  explicit PhysicsStep(const ModelConfig& step_of);
  std::string name() const override { return "one physics step"; }
  void begin(const dataset::Sequence& seq) override;
  Points step(const dataset::Sequence& seq, int t, const Points& x_prev2, const Points& x_prev,
              const Points& x_now) override;

 private:
  ModelConfig model_;  // velocity_base "physics", every other key at its default
  dataset::SampleOptions options_;
  std::shared_ptr<const dataset::SequenceStructure> structure_;
};

// The cloth constraints of `settings` (run/cloth_constraints.h) built for one sequence, the
// same for the network and for every baseline run with the post-processing.
std::unique_ptr<const ClothConstraints> make_cloth_constraints(const dataset::Sequence& seq,
                                                               const EvalConfig& settings);

// Any predictor followed by the model's post-processing (the cloth constraints with contact
// friction and pins, under `settings`, eval.constraints not read) after every predicted frame,
// exactly as the network's rollout applies it: a baseline compared with a post-processed model
// gets the same help. Named "[constrained] <inner name>".
class PostProcessed : public Predictor {
 public:
  PostProcessed(std::unique_ptr<Predictor> inner, EvalConfig settings)
      : inner_(std::move(inner)), settings_(std::move(settings)) {}
  std::string name() const override { return "[constrained] " + inner_->name(); }
  bool takes_scaled_wind() const override { return inner_->takes_scaled_wind(); }
  void begin(const dataset::Sequence& seq) override;
  Points step(const dataset::Sequence& seq, int t, const Points& x_prev2, const Points& x_prev,
              const Points& x_now) override;

 private:
  std::unique_ptr<Predictor> inner_;
  EvalConfig settings_;
  std::unique_ptr<const ClothConstraints> constraints_;
};

// The dataset sample of a rollout step: the window t-2..t+1 with the body from the data and the
// garments from the rollout (x_prev2, x_prev, x_now at t-2..t; t+1, the unused target, from the data),
// with what the model's velocity base needs (losses::add_physics_step).
dataset::TrainingSample rollout_sample(const dataset::Sequence& seq, int t, const Points& x_prev2, const Points& x_prev,
                                       const Points& x_now, const dataset::NormalisationStats& stats,
                                       const std::shared_ptr<const dataset::SequenceStructure>& structure,
                                       const dataset::SampleOptions& options, const ModelConfig& model);

// World x_{t+1} (N, 3) from a rollout sample: the model input in precision T, forward without
// recording on `tape`, predicted root-relative position + r_{t+1}.
template <class T>
Points predict_positions(ad::Tape<T>& tape, ad::ParamStore<T>& params, const Config& config,
                         const dataset::TrainingSample& sample, const dataset::NormalisationStats& stats);

// The network as a predictor, in precision T (float, or double for the precision check):
// builds the dataset sample of the rollout's window (rollout_sample), the model input, runs
// forward without recording; world x_{t+1} = predicted root-relative x + r_{t+1} (with
// eval.mirror_average, the mean of that and the mirrored prediction on the mirrored scene), then
// the patch tether when the config's eval.patch_tether > 0 (eval/tether.h), then the cloth
// constraints when eval.constraints is set (run/cloth_constraints.h).
template <class T>
class NetworkPredictor : public Predictor {
 public:
  void begin(const dataset::Sequence& seq) override;
  bool takes_scaled_wind() const override { return true; }
  Points step(const dataset::Sequence& seq, int t, const Points& x_prev2, const Points& x_prev,
              const Points& x_now) override;
  const Config& config() const { return config_; }
  const ad::ParamStore<T>& params() const { return params_; }
  const dataset::NormalisationStats& stats() const { return stats_; }
  // Patch tether factor of the following sequences (eval.patch_tether; 0 = off).
  void set_patch_tether(double factor) { config_.eval.patch_tether = factor; structure_.reset(); }
  // Cloth constraints on or off for the following sequences (eval.constraints).
  void set_constraints(bool on) { config_.eval.constraints = on; structure_.reset(); }
  // Rollout settings "eval.KEY=VALUE" for the following sequences; any other section throws
  // ConfigError (the model's keys are fixed by its weights).
  void apply_eval_settings(const std::vector<std::string>& assignments);

 protected:
  NetworkPredictor(Config config, ad::ParamStore<T> params, dataset::NormalisationStats stats);
  ad::Tape<T> tape_;

 private:
  Config config_;
  ad::ParamStore<T> params_;
  dataset::NormalisationStats stats_;
  dataset::SampleOptions sample_options_;
  std::shared_ptr<const dataset::SequenceStructure> structure_;
  std::vector<float> tether_limit_;  // (N,) eval.patch_tether > 0 only
  std::unique_ptr<const ClothConstraints> constraints_;  // eval.constraints only
  // eval.mirror_average only: the sequence's mirror image and its structure.
  std::unique_ptr<const dataset::Sequence> mirrored_;
  std::shared_ptr<const dataset::SequenceStructure> mirrored_structure_;
};
extern template class NetworkPredictor<float>;
extern template class NetworkPredictor<double>;

// The learned simulator in float32 (products optionally in bfloat16).
class ModelPredictor : public NetworkPredictor<float> {
 public:
  ModelPredictor(std::string name, Config config, ad::ParamStore<float> params, dataset::NormalisationStats stats);
  // The name, with "[bf16] " in front when the products run in bfloat16 (in front: tables
  // cut long names).
  std::string name() const override {
    return tape_.matmul_precision() == ad::MatmulPrecision::kBFloat16 ? "[bf16] " + name_ : name_;
  }
  // Precision of the linear layers' products (autodiff/bf16_gemm.h; default float32).
  void set_matmul_precision(ad::MatmulPrecision p) { tape_.set_matmul_precision(p); }

 private:
  std::string name_;
};

// Loads a checkpoint into a ModelPredictor. Statistics: the checkpoint's own when present,
// else `fallback_stats` (the data set's stats.h5); throws when neither exists.
std::unique_ptr<ModelPredictor> load_model_predictor(const std::string& checkpoint_path, const std::string& name,
                                                     const dataset::NormalisationStats* fallback_stats);

struct Rollout {
  int first_frame = 0;          // t0 + 1: the first predicted frame
  std::vector<Points> frames;   // (n,) predicted garment positions (N, 3), world
  std::vector<double> step_ms;  // (n,) wall time of each prediction, milliseconds
  // First rollout index whose prediction has a non-finite value, -1 if none. From there on
  // the predictor is not called again; the remaining frames are all NaN (step_ms 0).
  int diverged_at = -1;
};

// Rolls `predictor` over seq from input frame t0 (2 <= t0) for n frames, clamped so that
// t0 + n <= T − 1. Throws when not even one frame can be predicted.
// recorded_pins: when the sequence records its pinned vertices (SequenceInfo::pins_recorded),
// every predicted frame takes them from the data, as it takes the body: they are driven, not
// simulated, so every method gets them alike.
Rollout rollout(Predictor& predictor, const dataset::Sequence& seq, int t0, int n, bool recorded_pins = false);

}  // namespace layersnet::eval
