#include "run/config.h"

#include <toml++/toml.h>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <filesystem>
#include <functional>
#include <limits>
#include <sstream>
#include <type_traits>
#include <utility>

namespace layersnet {

namespace {

namespace fs = std::filesystem;

// Where a value came from, for error messages: "configs/tiny.toml:12:1" or "--set".
std::string where(const std::string& origin, const toml::node& node) {
  const auto& src = node.source();
  if (src.begin.line == 0) return origin;
  return origin + ":" + std::to_string(src.begin.line) + ":" + std::to_string(src.begin.column);
}

// One config key: how to read it from TOML into the struct, and how to print it.
struct KeySpec {
  std::string key;
  std::string type;
  std::string doc;
  std::function<void(Config&, const toml::node&, const std::string& at)> set;
  std::function<std::string(const Config&)> print;
};

template <class V>
std::string type_name() {
  if constexpr (std::is_same_v<V, bool>) return "bool";
  else if constexpr (std::is_integral_v<V>) return "integer";
  else if constexpr (std::is_floating_point_v<V>) return "float";
  else if constexpr (std::is_same_v<V, std::string>) return "string";
  else return "list of integers";
}

template <class V>
std::string print_value(const V& v) {
  std::ostringstream out;
  if constexpr (std::is_same_v<V, bool>) out << (v ? "true" : "false");
  else if constexpr (std::is_integral_v<V>) out << v;
  else if constexpr (std::is_floating_point_v<V>) {
    // Shortest text that reads back bit-exact.
    char buf[64];
    const auto end = std::to_chars(buf, buf + sizeof buf, v).ptr;
    const std::string s(buf, end);
    out << s;
    if (s.find_first_of(".eEn") == std::string::npos) out << ".0";  // keep it a TOML float
  } else if constexpr (std::is_same_v<V, std::string>) {
    out << toml::value<std::string>(v);
  } else {
    out << "[";
    for (std::size_t k = 0; k < v.size(); ++k) out << (k ? ", " : "") << v[k];
    out << "]";
  }
  return out.str();
}

struct Range {
  double min = -std::numeric_limits<double>::infinity();
  double max = std::numeric_limits<double>::infinity();
  std::vector<std::string> choices;  // strings only
};

template <class V>
V read_value(const toml::node& node, const std::string& key, const std::string& at, const Range& range) {
  auto bad_type = [&] {
    return ConfigError(at + ": key '" + key + "' must be " + (std::is_same_v<V, std::vector<int>> ? "a " : "a ") +
                       type_name<V>());
  };
  auto check_range = [&](double x) {
    if (!(x >= range.min && x <= range.max)) {
      std::ostringstream msg;
      msg << at << ": key '" << key << "' = " << x << " is out of range [" << range.min << ", " << range.max << "]";
      throw ConfigError(msg.str());
    }
  };
  if constexpr (std::is_same_v<V, bool>) {
    if (!node.is_boolean()) throw bad_type();
    return node.as_boolean()->get();
  } else if constexpr (std::is_integral_v<V>) {
    if (!node.is_integer()) throw bad_type();
    const int64_t x = node.as_integer()->get();
    check_range(static_cast<double>(x));
    return static_cast<V>(x);
  } else if constexpr (std::is_floating_point_v<V>) {
    if (!node.is_number()) throw bad_type();
    const double x = node.is_integer() ? static_cast<double>(node.as_integer()->get()) : node.as_floating_point()->get();
    if (!std::isfinite(x)) throw ConfigError(at + ": key '" + key + "' must be finite");
    check_range(x);
    return static_cast<V>(x);
  } else if constexpr (std::is_same_v<V, std::string>) {
    if (!node.is_string()) throw bad_type();
    std::string s = node.as_string()->get();
    if (!range.choices.empty() && std::find(range.choices.begin(), range.choices.end(), s) == range.choices.end()) {
      std::string list;
      for (const auto& c : range.choices) list += (list.empty() ? "" : ", ") + ("\"" + c + "\"");
      throw ConfigError(at + ": key '" + key + "' = \"" + s + "\" is not one of " + list);
    }
    return s;
  } else {
    if (!node.is_array()) throw bad_type();
    V out;
    for (const auto& element : *node.as_array()) {
      if (!element.is_integer()) throw bad_type();
      const int64_t x = element.as_integer()->get();
      check_range(static_cast<double>(x));
      out.push_back(static_cast<int>(x));
    }
    return out;
  }
}

class Schema {
 public:
  template <class Field>
  void add(const std::string& key, Field field, const std::string& doc, Range range = {}) {
    using V = std::remove_reference_t<decltype(field(std::declval<Config&>()))>;
    KeySpec spec;
    spec.key = key;
    spec.type = type_name<V>();
    spec.doc = doc;
    spec.set = [field, key, range](Config& c, const toml::node& node, const std::string& at) {
      field(c) = read_value<V>(node, key, at, range);
    };
    spec.print = [field](const Config& c) { return print_value(field(const_cast<Config&>(c))); };
    specs_.push_back(std::move(spec));
  }
  const std::vector<KeySpec>& specs() const { return specs_; }
  const KeySpec* find(const std::string& key) const {
    for (const auto& s : specs_)
      if (s.key == key) return &s;
    return nullptr;
  }

 private:
  std::vector<KeySpec> specs_;
};

const Schema& schema() {
  static const Schema s = [] {
    Schema k;
    const Range positive{1, 1e9, {}};
    // [model]
    k.add("model.width", [](Config& c) -> int& { return c.model.width; }, "token channels d", {8, 4096, {}});
    k.add("model.heads", [](Config& c) -> int& { return c.model.heads; }, "attention heads (even: world + mesh)", {2, 64, {}});
    k.add("model.layers", [](Config& c) -> int& { return c.model.layers; }, "simulator transformer layers", {1, 64, {}});
    k.add("model.ffn_width", [](Config& c) -> int& { return c.model.ffn_width; }, "FFN hidden width", positive);
    k.add("model.decoder_width", [](Config& c) -> int& { return c.model.decoder_width; }, "decoder MLP width", positive);
    k.add("model.patch_size", [](Config& c) -> double& { return c.model.patch_size; }, "UV patch cell size", {1e-4, 10, {}});
    k.add("model.world_radius", [](Config& c) -> double& { return c.model.world_radius; }, "patch world-edge radius R (scene units)", {0, 100, {}});
    k.add("model.body_radius", [](Config& c) -> double& { return c.model.body_radius; }, "patch-to-body radius R_b (scene units)", {0, 100, {}});
    k.add("model.body_neighbors", [](Config& c) -> int& { return c.model.body_neighbors; }, "body vertices per patch K (>= 1: the body is the model's only contact information)", {1, 256, {}});
    k.add("model.body_query", [](Config& c) -> std::string& { return c.model.body_query; }, "which K body vertices: nearest, or first in index order (official)", {0, 0, {"nearest", "first"}});
    k.add("model.decoder_patch_candidates", [](Config& c) -> int& { return c.model.decoder_patch_candidates; }, "patches decoding each vertex", {1, 64, {}});
    k.add("model.attention", [](Config& c) -> std::string& { return c.model.attention; }, "attention normalisation", {0, 0, {"ria", "tie"}});
    k.add("model.rotation_equivalent", [](Config& c) -> bool& { return c.model.rotation_equivalent; }, "Rotation Equivalent Transformation on/off");
    k.add("model.decoder_ret_channels", [](Config& c) -> int& { return c.model.decoder_ret_channels; }, "3-vector channels of the decoder's RET (official 1; 3k <= width)", {1, 1024, {}});
    k.add("model.vertex_local_features", [](Config& c) -> bool& { return c.model.vertex_local_features; }, "the decoder also sees each vertex's nearest body motion, spring force and Laplacians (not in the paper)");
    k.add("model.velocity_base", [](Config& c) -> std::string& { return c.model.velocity_base; }, "what a zero network output predicts: the cloth keeps its velocity (inertia, official), moves with the body surface (body), keeps its velocity relative to the body surface (body_inertia), or takes one implicit step of Blender's cloth energy (physics)", {0, 0, {"inertia", "body", "body_inertia", "physics"}});
    k.add("model.physics_step_cg_iterations", [](Config& c) -> int& { return c.model.physics_step_cg_iterations; }, "conjugate-gradient iterations of each Newton iteration of the physics step (read with velocity_base physics only)", {1, 10000, {}});
    k.add("model.physics_step_iterations", [](Config& c) -> int& { return c.model.physics_step_iterations; }, "Newton iterations of the physics step (read with velocity_base physics only)", {0, 100, {}});
    k.add("model.physics_step_substeps", [](Config& c) -> int& { return c.model.physics_step_substeps; }, "implicit steps per frame of the physics step, each of 1/substeps frame (read with velocity_base physics only)", {1, 100, {}});
    k.add("model.physics_step_collision_stiffness", [](Config& c) -> double& { return c.model.physics_step_collision_stiffness; }, "the physics step's body-contact stiffness k_c (mass / frame^2; read with velocity_base physics only)", {0, 1e9, {}});
    k.add("model.physics_step_layer_collision", [](Config& c) -> bool& { return c.model.physics_step_layer_collision; }, "the physics step also pushes the outer layer out of the inner one (read with velocity_base physics only)");
    k.add("model.physics_step_layer_stiffness", [](Config& c) -> double& { return c.model.physics_step_layer_stiffness; }, "the physics step's layer term stiffness as a factor on physics_step_collision_stiffness (with physics_step_layer_collision)", {0, 1e6, {}});
    k.add("model.physics_step_layer_margin", [](Config& c) -> double& { return c.model.physics_step_layer_margin; }, "scene units the physics step's layer term keeps the outer layer outside the inner one (with physics_step_layer_collision)", {0, 10, {}});
    k.add("model.physics_step_friction", [](Config& c) -> double& { return c.model.physics_step_friction; }, "the physics step's contact friction: cloth within physics_step_friction_distance of the body is held to its tangential motion with this stiffness x the vertex mass (0 = frictionless; read with velocity_base physics only)", {0, 1e6, {}});
    k.add("model.physics_step_face_wind", [](Config& c) -> double& { return c.model.physics_step_face_wind; }, "the physics step's face wind: each triangle gives each corner this x area / 3 x (w.n) n (Blender's is 0.02; twice it is closest to Blender for one step per frame)", {0, 1, {}});
    k.add("model.physics_step_bending", [](Config& c) -> double& { return c.model.physics_step_bending; }, "factor on the physics step's bending stiffness (1 = the energy's hinges, k = bending x edge length x 0.1; 0.25 is closest to Blender on large val)", {0, 100, {}});
    k.add("model.physics_step_stretch", [](Config& c) -> double& { return c.model.physics_step_stretch; }, "factor on the physics step's spring stiffness (1 = the energy's springs, k = tension / rest length; read with velocity_base physics only)", {0, 100, {}});
    k.add("model.physics_step_bending_by_height", [](Config& c) -> bool& { return c.model.physics_step_bending_by_height; }, "each hinge's bending stiffness in the physics step times its rest height over the edge, so that it pushes as hard as Blender's angular spring (off: the energy's gradient, 1/height times as hard)");
    k.add("model.physics_step_friction_distance", [](Config& c) -> double& { return c.model.physics_step_friction_distance; }, "scene units from the body surface (along its normal) within which the physics step's friction acts", {0, 10, {}});
    k.add("model.physics_step_correction", [](Config& c) -> std::string& { return c.model.physics_step_correction; }, "how the network's correction joins the physics step: added after it, or solved through its last Newton system, so that springs and bending resist a correction that stretches or folds the cloth (needs velocity_base physics, one substep, no output_smoothing)", {0, 0, {"added", "solved"}});
    k.add("model.physics_step_pins", [](Config& c) -> std::string& { return c.model.physics_step_pins; }, "where the physics step puts pinned vertices at t+1: carried with the body surface under them, or recorded (where the sequence's frames say its simulator drove them; scenes without recorded frames, as simulate builds, fall back to carried; read with velocity_base physics only)", {0, 0, {"carried", "recorded"}});
    k.add("model.physics_step_inertia", [](Config& c) -> std::string& { return c.model.physics_step_inertia; }, "the physics step's inertia target: the cloth's velocity relative to the body surface kept (body) or Blender's 2x_t - x_{t-1} (world; read with velocity_base physics only)", {0, 0, {"body", "world"}});
    k.add("model.swing_kept", [](Config& c) -> double& { return c.model.swing_kept; }, "share of the cloth's velocity relative to the body surface that a zero output keeps (velocity_base body_inertia; 1 = all, 0 = the body base)", {0, 1, {}});
    k.add("model.carry_smoothing", [](Config& c) -> int& { return c.model.carry_smoothing; }, "averaging steps over the garment mesh on the body carry (velocity_base body or body_inertia); 0 = none", {0, 1000, {}});
    k.add("model.output_smoothing", [](Config& c) -> int& { return c.model.output_smoothing; }, "averaging steps over the garment mesh on the network's per-vertex correction (not in the paper); 0 = none", {0, 1000, {}});
    k.add("model.patch_base_input", [](Config& c) -> bool& { return c.model.patch_base_input; }, "each patch token also sees its velocity base (the patch mean of the body carry or of the physics step; velocity_base body, body_inertia or physics; not in the paper)");
    k.add("model.vertex_base_input", [](Config& c) -> bool& { return c.model.vertex_base_input; }, "the decoder's vertex rows also see their own vertex's velocity base, in their frame (velocity_base body, body_inertia or physics; not in the paper)");
    k.add("model.wind_force_input", [](Config& c) -> bool& { return c.model.wind_force_input; }, "each garment vertex and patch also sees the wind's force on its faces, as Blender applies it (not in the paper)");
    k.add("model.orthogonality", [](Config& c) -> std::string& { return c.model.orthogonality; }, "how W_R stays orthogonal", {0, 0, {"penalty", "exact"}});
    // [loss]
    const Range weight{0, 1e6, {}};
    k.add("loss.vertex", [](Config& c) -> double& { return c.loss.vertex; }, "vertex position MSE weight", weight);
    k.add("loss.patch", [](Config& c) -> double& { return c.loss.patch; }, "patch centre MSE weight", weight);
    k.add("loss.normal", [](Config& c) -> double& { return c.loss.normal; }, "vertex normal loss weight", weight);
    k.add("loss.collision_body", [](Config& c) -> double& { return c.loss.collision_body; }, "garment-body collision weight", weight);
    k.add("loss.collision_layer", [](Config& c) -> double& { return c.loss.collision_layer; }, "outer-inner layer collision weight", weight);
    k.add("loss.layer_mean_over", [](Config& c) -> std::string& { return c.loss.layer_mean_over; }, "what the layer collision sum is divided by: the outer vertices that collide (colliding, eq. 18) or every outer vertex (outer; not in the paper)", {0, 0, {"colliding", "outer"}});
    k.add("loss.collision_eps", [](Config& c) -> double& { return c.loss.collision_eps; }, "collision margin d_eps (scene units)", {0, 10, {}});
    k.add("loss.orthogonality", [](Config& c) -> double& { return c.loss.orthogonality; }, "W_R orthogonality penalty weight", weight);
    k.add("loss.relative_to_base", [](Config& c) -> bool& { return c.loss.relative_to_base; }, "divide each sample's vertex and patch terms by its zero-output prediction's error (not in the paper)");
    k.add("loss.self_fed_truth", [](Config& c) -> double& { return c.loss.self_fed_truth; }, "weight of the vertex, patch and normal terms on samples whose input is the model's own prediction (T_n > 0; 1 = as the paper, 0 = the physics energy and the collision terms alone score them)", {0, 1, {}});
    k.add("loss.edge_strain", [](Config& c) -> double& { return c.loss.edge_strain; }, "edge-length strain weight (not in the paper; 0 = off)", weight);
    // [physics]
    k.add("physics.weight", [](Config& c) -> double& { return c.physics.weight; }, "weight of the physics energy (losses/physics.h, per garment vertex) beside the supervised loss; 0 = off", weight);
    k.add("physics.ramp_steps", [](Config& c) -> int& { return c.physics.ramp_steps; }, "physics.weight grows linearly from 0 over this many updates (0 = at once)", {0, 1e9, {}});
    k.add("physics.self_fed_only", [](Config& c) -> bool& { return c.physics.self_fed_only; }, "score the physics energy only on samples whose input is the model's own prediction (T_n > 0)");
    k.add("physics.inertia", [](Config& c) -> double& { return c.physics.inertia; }, "physics: inertia term weight (1 = as the simulator)", weight);
    k.add("physics.drag", [](Config& c) -> double& { return c.physics.drag; }, "physics: air drag term weight", weight);
    k.add("physics.stretch", [](Config& c) -> double& { return c.physics.stretch; }, "physics: structural spring term weight", weight);
    k.add("physics.bending", [](Config& c) -> double& { return c.physics.bending; }, "physics: angular bending term weight", weight);
    k.add("physics.gravity", [](Config& c) -> double& { return c.physics.gravity; }, "physics: gravity work term weight", weight);
    k.add("physics.wind", [](Config& c) -> double& { return c.physics.wind; }, "physics: wind work term weight", weight);
    k.add("physics.collision_body", [](Config& c) -> double& { return c.physics.collision_body; }, "physics: body collision penalty weight", weight);
    k.add("physics.collision_layer", [](Config& c) -> double& { return c.physics.collision_layer; }, "physics: outer-inner layer collision penalty weight", weight);
    k.add("physics.friction", [](Config& c) -> double& { return c.physics.friction; }, "physics: contact friction term weight (the physics step's model.physics_step_friction within model.physics_step_friction_distance of the body; needs model.velocity_base = \"physics\"; 0 = none)", weight);
    k.add("physics.bending_by_height", [](Config& c) -> bool& { return c.physics.bending_by_height; }, "physics: each hinge's bending stiffness times its rest height over the edge, so that it pushes as hard as Blender's angular spring (off: the energy's gradient, 1/height times as hard)");
    k.add("physics.air_damping", [](Config& c) -> double& { return c.physics.air_damping; }, "physics: the simulator's air damping (Blender default 1)", {0, 1e6, {}});
    k.add("physics.body_margin", [](Config& c) -> double& { return c.physics.body_margin; }, "physics: distance kept from the body (scene units; Blender's push-out distance of the generator's settings)", {0, 10, {}});
    k.add("physics.layer_margin", [](Config& c) -> double& { return c.physics.layer_margin; }, "physics: distance kept between the layers (scene units)", {0, 10, {}});
    k.add("physics.collision_stiffness_start", [](Config& c) -> double& { return c.physics.collision_stiffness_start; }, "physics: collision stiffness k_c before the ramp", {0, 1e12, {}});
    k.add("physics.collision_stiffness_max", [](Config& c) -> double& { return c.physics.collision_stiffness_max; }, "physics: collision stiffness k_c after the ramp", {0, 1e12, {}});
    k.add("physics.collision_ramp_start", [](Config& c) -> int& { return c.physics.collision_ramp_start; }, "physics: updates before k_c starts growing", {0, 1e9, {}});
    k.add("physics.collision_ramp_steps", [](Config& c) -> int& { return c.physics.collision_ramp_steps; }, "physics: updates over which k_c grows linearly from start to max (0 = at once)", {0, 1e9, {}});
    // [data]
    k.add("data.dataset", [](Config& c) -> std::string& { return c.data.dataset; }, "data set folder");
    k.add("data.stats", [](Config& c) -> std::string& { return c.data.stats; }, "statistics file to train with (empty: DATASET/stats.h5, from the training split)");
    k.add("data.first_frame", [](Config& c) -> int& { return c.data.first_frame; }, "first input frame of a sample", {2, 1e6, {}});
    k.add("data.max_frames", [](Config& c) -> int& { return c.data.max_frames; }, "frames used per sequence (0 = all)", {0, 1e6, {}});
    k.add("data.after_ramp", [](Config& c) -> bool& { return c.data.after_ramp; }, "samples start where each file's ramp into the motion ends (rest_frames + ramp_frames - 1 as first input frame), as eval's rollouts do");
    k.add("data.cache_sequences", [](Config& c) -> int& { return c.data.cache_sequences; }, "sequences cached in memory", positive);
    k.add("data.mirror", [](Config& c) -> bool& { return c.data.mirror; }, "train on every training sequence and on its mirror image in the plane x = 0 (twice the sequences; validation and test unchanged)");
    // [train]
    k.add("train.epochs", [](Config& c) -> int& { return c.train.epochs; }, "epochs", positive);
    k.add("train.batch_size", [](Config& c) -> int& { return c.train.batch_size; }, "samples per update (each holds its own tape: thousands exhaust memory)", {1, 4096, {}});
    k.add("train.learning_rate", [](Config& c) -> double& { return c.train.learning_rate; }, "Adam learning rate", {0, 10, {}});
    k.add("train.lr_decay_epochs", [](Config& c) -> std::vector<int>& { return c.train.lr_decay_epochs; }, "epochs after which lr *= lr_gamma", {1, 1e6, {}});
    k.add("train.lr_gamma", [](Config& c) -> double& { return c.train.lr_gamma; }, "step decay factor", {0, 1, {}});
    k.add("train.lr_warmup_updates", [](Config& c) -> int& { return c.train.lr_warmup_updates; }, "the run's first this many updates ramp the learning rate linearly up to its value (0 = off)", {0, 1e9, {}});
    k.add("train.adam_beta1", [](Config& c) -> double& { return c.train.adam_beta1; }, "Adam beta1", {0, 0.999999, {}});
    k.add("train.adam_beta2", [](Config& c) -> double& { return c.train.adam_beta2; }, "Adam beta2", {0, 0.999999999, {}});
    k.add("train.adam_eps", [](Config& c) -> double& { return c.train.adam_eps; }, "Adam epsilon", {0, 1, {}});
    k.add("train.ema_decay", [](Config& c) -> double& { return c.train.ema_decay; }, "keep a moving average of the weights, a = d a + (1 - d) w after every update; validation and best.h5 use it (0 = off)", {0, 0.9999, {}});
    k.add("train.grad_clip", [](Config& c) -> double& { return c.train.grad_clip; }, "global gradient norm clip (0 = off)", {0, 1e9, {}});
    k.add("train.rollout_steps", [](Config& c) -> std::vector<int>& { return c.train.rollout_steps; }, "max self-fed steps T_n per epoch", {0, 1000, {}});
    k.add("train.rollout_constraints", [](Config& c) -> bool& { return c.train.rollout_constraints; }, "project self-fed frames (curriculum and validation rollouts) onto the cloth constraints (eval.strain_limit, eval.collision_shell, ...)");
    k.add("train.bptt_steps", [](Config& c) -> int& { return c.train.bptt_steps; }, "the last this many self-fed steps are recorded and the loss's gradient flows back through them (0 = only the final step's, official)", {0, 1000, {}});
    k.add("train.bptt_score_every_step", [](Config& c) -> bool& { return c.train.bptt_score_every_step; }, "with bptt_steps: score every recorded self-fed step against its ground truth, the loss being the mean with the final step's (false: the final step's only)");
    k.add("train.input_noise", [](Config& c) -> double& { return c.train.input_noise; }, "std of noise on the input garment positions (scene units, 0 = off)", {0, 1e3, {}});
    k.add("train.init_from", [](Config& c) -> std::string& { return c.train.init_from; }, "checkpoint or packed model whose weights (by name; weights it lacks start at zero) and statistics start a new run; empty = random init");
    k.add("train.seed", [](Config& c) -> int64_t& { return c.train.seed; }, "random seed", {0, 9.0e15, {}});
    k.add("train.threads", [](Config& c) -> int& { return c.train.threads; }, "OpenMP threads (0 = all)", {0, 1024, {}});
    k.add("train.keep_checkpoints", [](Config& c) -> int& { return c.train.keep_checkpoints; }, "last N checkpoints kept", positive);
    k.add("train.checkpoint_every", [](Config& c) -> int& { return c.train.checkpoint_every; }, "updates between checkpoints (0 = epoch ends only)", {0, 1e9, {}});
    k.add("train.epoch_checkpoints", [](Config& c) -> bool& { return c.train.epoch_checkpoints; }, "checkpoint at each epoch end (false: only the last epoch)");
    k.add("train.validate", [](Config& c) -> bool& { return c.train.validate; }, "one-step validation error after each epoch");
    k.add("train.validate_initial", [](Config& c) -> bool& { return c.train.validate_initial; }, "also validate the model before its first update, so that best.h5 is the untrained model (its velocity base) when no update beats it");
    k.add("train.val_samples", [](Config& c) -> int& { return c.train.val_samples; }, "validation samples, evenly spaced (0 = all)", {0, 1e9, {}});
    k.add("train.val_rollout_frames", [](Config& c) -> int& { return c.train.val_rollout_frames; }, "validate by a self-fed rollout of up to this many frames per val sequence, predicting from the end of the file's ramp if it has one (0 = one-step error)", {0, 1e6, {}});
    k.add("train.epoch_samples", [](Config& c) -> int64_t& { return c.train.epoch_samples; }, "samples per epoch, the first of each epoch's shuffled order, so every epoch draws another subset (0 = all)", {0, 9.0e15, {}});
    k.add("train.max_steps", [](Config& c) -> int& { return c.train.max_steps; }, "stop once the run has this many updates in total, counting those before a --resume (0 = no limit)", {0, 1e9, {}});
    k.add("train.max_nonfinite_in_row", [](Config& c) -> int& { return c.train.max_nonfinite_in_row; }, "stop after this many non-finite steps in a row", positive);
    k.add("train.log_every", [](Config& c) -> int& { return c.train.log_every; }, "steps between progress lines", positive);
    // [eval]
    k.add("eval.split", [](Config& c) -> std::string& { return c.eval.split; }, "split to evaluate", {0, 0, {"train", "val", "test"}});
    k.add("eval.frames", [](Config& c) -> int& { return c.eval.frames; }, "predicted frames per sequence", positive);
    k.add("eval.patch_tether", [](Config& c) -> double& { return c.eval.patch_tether; }, "rollouts keep each vertex within this many rest patch radii of its patch centre (0 = off, the default; eval/tether.h)", {0, 1e6, {}});
    k.add("eval.constraints", [](Config& c) -> bool& { return c.eval.constraints; }, "rollouts project every predicted frame onto the cloth constraints: edge strain limit, collision shell (run/cloth_constraints.h; not in the paper)");
    k.add("eval.strain_limit", [](Config& c) -> double& { return c.eval.strain_limit; }, "constraints: largest |edge length / rest length - 1| a rollout keeps (0 = no edge step)", {0, 0.99, {}});
    k.add("eval.fold_limit", [](Config& c) -> double& { return c.eval.fold_limit; }, "constraints: largest relative shortening of the distance between the far corners of two triangles sharing an edge (0 = no fold step)", {0, 0.99, {}});
    k.add("eval.recorded_pins", [](Config& c) -> bool& { return c.eval.recorded_pins; }, "rollouts: every method's pinned vertices are where the sequence records them at each frame (driven like the body; sequences without recorded frames, as simulate builds, are left to the method and the constraints' pins); eval compares every method under the first model's setting");
    k.add("eval.pins", [](Config& c) -> bool& { return c.eval.pins; }, "constraints: vertices the file pins (/garments/<name>/pin >= 0.5: waistbands, top edges) move rigidly with the body under them, as the simulator that made the data moved them");
    k.add("eval.collision_shell", [](Config& c) -> double& { return c.eval.collision_shell; }, "constraints: scene units a rollout keeps garments outside the body and the outer layer outside the inner one (0 = no collision step)", {0, 10, {}});
    k.add("eval.body_friction", [](Config& c) -> double& { return c.eval.body_friction; }, "constraints: share of a near-body garment vertex's tangential motion relative to the body that the body takes away (0 = off, 1 = the vertex sticks)", {0, 1, {}});
    k.add("eval.layer_friction", [](Config& c) -> double& { return c.eval.layer_friction; }, "constraints: the same as eval.body_friction for an outer-layer vertex against the inner layer (0 = off)", {0, 1, {}});
    k.add("eval.friction_distance", [](Config& c) -> double& { return c.eval.friction_distance; }, "constraints: scene units from the body surface (along its normal) within which eval.body_friction acts", {0, 10, {}});
    k.add("eval.mirror_average", [](Config& c) -> bool& { return c.eval.mirror_average; }, "rollouts: each frame the mean of the network's prediction and the mirror image of its prediction on the mirrored scene (symmetric under mirrors as the cloth is; twice the time per frame)");
    k.add("eval.correction_scale", [](Config& c) -> double& { return c.eval.correction_scale; }, "rollouts: factor on the network's output, the correction of its velocity base (1 = as trained, 0 = the base alone)", {0, 10, {}});
    k.add("eval.constraint_iterations", [](Config& c) -> int& { return c.eval.constraint_iterations; }, "constraints: at most this many projection passes per predicted frame (they stop after one that moves nothing)", {1, 1000, {}});
    return k;
  }();
  return s;
}

std::size_t edit_distance(const std::string& a, const std::string& b) {
  std::vector<std::size_t> row(b.size() + 1);
  for (std::size_t j = 0; j <= b.size(); ++j) row[j] = j;
  for (std::size_t i = 1; i <= a.size(); ++i) {
    std::size_t diag = row[0];
    row[0] = i;
    for (std::size_t j = 1; j <= b.size(); ++j) {
      const std::size_t up = row[j];
      row[j] = std::min({row[j] + 1, row[j - 1] + 1, diag + (a[i - 1] == b[j - 1] ? 0 : 1)});
      diag = up;
    }
  }
  return row[b.size()];
}

std::string closest_key(const std::string& key) {
  std::string best;
  std::size_t best_d = std::numeric_limits<std::size_t>::max();
  for (const auto& s : schema().specs()) {
    const std::size_t d = edit_distance(key, s.key);
    if (d < best_d) best_d = d, best = s.key;
  }
  return best;
}

void apply_value(Config& config, const std::string& key, const toml::node& node, const std::string& at) {
  const KeySpec* spec = schema().find(key);
  if (!spec) throw ConfigError(at + ": unknown key '" + key + "'; did you mean '" + closest_key(key) + "'?");
  spec->set(config, node, at);
  config.set_at[key] = at;
}

void apply_table(Config& config, const toml::table& table, const std::string& prefix, const std::string& origin) {
  for (auto&& [name, node] : table) {
    const std::string key = prefix.empty() ? std::string(name.str()) : prefix + "." + std::string(name.str());
    if (prefix.empty() && key == "include") continue;  // handled by apply_config_file
    if (node.is_table()) {
      apply_table(config, *node.as_table(), key, origin);
    } else {
      apply_value(config, key, node, where(origin, node));
    }
  }
}

void apply_file(Config& config, const fs::path& path, std::vector<fs::path>& stack) {
  const fs::path canonical = fs::weakly_canonical(path);
  if (std::find(stack.begin(), stack.end(), canonical) != stack.end())
    throw ConfigError(path.string() + ": include cycle (the file includes itself, directly or through its bases)");
  if (!fs::exists(path) || fs::is_directory(path)) {
    const std::string from = stack.empty() ? "" : " (included from " + stack.back().string() + ")";
    throw ConfigError(path.string() + (fs::exists(path) ? ": is a directory, not a config file" : ": config file not found") +
                      from);
  }
  toml::table table;
  try {
    table = toml::parse_file(path.string());
  } catch (const toml::parse_error& e) {
    std::ostringstream msg;
    msg << path.string() << ":" << e.source().begin.line << ":" << e.source().begin.column << ": " << e.description();
    throw ConfigError(msg.str());
  }
  stack.push_back(canonical);
  if (const toml::node* inc = table.get("include")) {
    std::vector<std::string> bases;
    if (inc->is_string()) {
      bases.push_back(inc->as_string()->get());
    } else if (inc->is_array()) {
      for (const auto& b : *inc->as_array()) {
        if (!b.is_string()) throw ConfigError(where(path.string(), *inc) + ": 'include' must be a string or a list of strings");
        bases.push_back(b.as_string()->get());
      }
    } else {
      throw ConfigError(where(path.string(), *inc) + ": 'include' must be a string or a list of strings");
    }
    for (const auto& base : bases) apply_file(config, path.parent_path() / base, stack);
  }
  apply_table(config, table, "", path.string());
  stack.pop_back();
}

}  // namespace

void apply_config_file(Config& config, const std::string& path) {
  std::vector<fs::path> stack;
  apply_file(config, path, stack);
}

Config parse_config_text(const std::string& toml_text, const std::string& origin) {
  toml::table table;
  try {
    table = toml::parse(toml_text, origin);
  } catch (const toml::parse_error& e) {
    std::ostringstream msg;
    msg << origin << ":" << e.source().begin.line << ":" << e.source().begin.column << ": " << e.description();
    throw ConfigError(msg.str());
  }
  if (table.contains("include")) throw ConfigError(origin + ": 'include' is not allowed in an embedded config");
  Config config;
  apply_table(config, table, "", origin);
  apply_saved_config_defaults(config, toml_text);
  validate_config(config);
  return config;
}

void apply_saved_config_defaults(Config& config, const std::string& saved_toml_text) {
  if (saved_toml_text.find("decoder_ret_channels") == std::string::npos) config.model.decoder_ret_channels = 1;
  if (saved_toml_text.find("val_rollout_frames") == std::string::npos) config.train.val_rollout_frames = 0;
}

namespace {
// The key of a "section.key=value" assignment, trailing blanks removed.
std::string override_key(const std::string& assignment) {
  const auto eq = assignment.find('=');
  if (eq == std::string::npos || eq == 0)
    throw ConfigError("--set " + assignment + ": expected key=value, e.g. --set train.epochs=2");
  std::string key = assignment.substr(0, eq);
  key.erase(key.find_last_not_of(" \t") + 1);
  return key;
}
}  // namespace

void apply_override(Config& config, const std::string& assignment) {
  const std::string key = override_key(assignment);
  const std::string text = assignment.substr(assignment.find('=') + 1);
  const std::string at = "--set " + assignment;
  toml::table parsed;
  try {
    parsed = toml::parse("value = " + text);
  } catch (const toml::parse_error&) {
    // A bare word such as data/default or nearest: take it as a string.
    parsed = toml::table{{"value", text}};
  }
  apply_value(config, key, *parsed.get("value"), at);
}

void apply_rollout_override(Config& config, const std::string& assignment) {
  const std::string key = override_key(assignment);
  // The step's conjugate-gradient count belongs to the solver, not to the weights: fewer
  // iterations trade accuracy for speed (docs/decisions.md, "Fewer conjugate-gradient iterations
  // on the softer step"). Where its pins come from belongs to the scene: a model trained on
  // recorded pins meets carried ones wherever a scene records none.
  if (key.rfind("eval.", 0) != 0 && key != "model.physics_step_cg_iterations" && key != "model.physics_step_pins")
    throw ConfigError("--set " + assignment + ": only rollout settings (eval.*, model.physics_step_cg_iterations and "
                      "model.physics_step_pins) can change for a trained model; the other keys are fixed by its weights "
                      "and training");
  apply_override(config, assignment);
}

void validate_config(const Config& config) {
  auto key = [&](const std::string& k, auto value) {
    std::ostringstream s;
    s << k << " = " << value;
    const auto it = config.set_at.find(k);
    s << " (" << (it == config.set_at.end() ? "default" : "set at " + it->second) << ")";
    return s.str();
  };
  const ModelConfig& m = config.model;
  if (m.heads % 2 != 0)
    throw ConfigError(key("model.heads", m.heads) + ": the heads are half world, half mesh, so their number must be "
                      "even; set 2, 4, 6, ...");
  if (m.width % m.heads != 0)
    throw ConfigError(key("model.width", m.width) + " is not a multiple of " + key("model.heads", m.heads) +
                      ": every head takes width / heads channels; set model.width to " +
                      std::to_string(m.width / m.heads * m.heads) + " or " +
                      std::to_string((m.width / m.heads + 1) * m.heads));
  if (m.swing_kept != 1.0 && m.velocity_base != "body_inertia")
    throw ConfigError(key("model.swing_kept", m.swing_kept) + " scales the relative velocity that only " +
                      key("model.velocity_base", "\"body_inertia\"") + " keeps, but " +
                      key("model.velocity_base", "\"" + m.velocity_base + "\"") +
                      "; set model.velocity_base = \"body_inertia\" or leave model.swing_kept at 1");
  for (const auto& [name, on] : {std::pair{"model.patch_base_input", m.patch_base_input},
                                  std::pair{"model.vertex_base_input", m.vertex_base_input}})
    if (on && m.velocity_base == "inertia")
      throw ConfigError(key(name, "true") + " gives the network its velocity base, but " +
                        key("model.velocity_base", "\"inertia\"") + " carries none; set model.velocity_base = \"physics\", "
                        "\"body\" or \"body_inertia\", or " + name + " = false");
  if (config.loss.self_fed_truth == 0 && config.physics.weight == 0)
    throw ConfigError(key("loss.self_fed_truth", 0) + " takes the ground truth away from the self-fed samples, and " +
                      key("physics.weight", 0) + " gives them no energy in its place; set physics.weight > 0 "
                      "(e.g. 0.1) or loss.self_fed_truth > 0");
  if (config.physics.friction > 0 && m.velocity_base != "physics")
    throw ConfigError(key("physics.friction", config.physics.friction) + " holds touching cloth where the body carries it, "
                      "as the physics step does, but " + key("model.velocity_base", "\"" + m.velocity_base + "\"") +
                      " carries no physics step; set model.velocity_base = \"physics\" or physics.friction = 0");
  if (m.physics_step_correction == "solved") {
    const std::string what = key("model.physics_step_correction", "\"solved\"") + " passes the correction through the physics step's linear system, but ";
    if (m.velocity_base != "physics")
      throw ConfigError(what + key("model.velocity_base", "\"" + m.velocity_base + "\"") +
                        " takes no physics step; set model.velocity_base = \"physics\" or model.physics_step_correction = \"added\"");
    if (m.physics_step_substeps != 1)
      throw ConfigError(what + key("model.physics_step_substeps", m.physics_step_substeps) +
                        " makes several systems; set model.physics_step_substeps = 1 or model.physics_step_correction = \"added\"");
    if (m.output_smoothing > 0)
      throw ConfigError(what + key("model.output_smoothing", m.output_smoothing) +
                        " smooths the same correction another way; set model.output_smoothing = 0 or "
                        "model.physics_step_correction = \"added\"");
  }
  if (m.rotation_equivalent && 3 * m.decoder_ret_channels > m.width)
    throw ConfigError(key("model.decoder_ret_channels", m.decoder_ret_channels) + " needs 3 x that many channels, more "
                      "than " + key("model.width", m.width) + "; set model.decoder_ret_channels <= " +
                      std::to_string(m.width / 3));
}

Config load_config(const std::vector<std::string>& files, const std::vector<std::string>& overrides) {
  Config config;
  for (const auto& f : files) apply_config_file(config, f);
  for (const auto& o : overrides) apply_override(config, o);
  validate_config(config);
  return config;
}

std::vector<std::string> config_warnings(const Config& config) {
  // A patch of model.patch_size s spans s metres of rest cloth: s * 10 scene units (D-LAYERS
  // scale). The outer layer's patch centres lie up to ~0.7 of that sideways from the nearest
  // inner-layer centre, plus the layer gap: on the default data a radius of one extent lets every
  // outer patch over the inner garment reach an inner patch (s = 0.1, 0.15), two extents cost
  // 8x the world edges for none more. The same extent gives every patch touching the body a
  // body neighbour at every patch size measured.
  const double extent = config.model.patch_size * 10.0;
  const double slack = 1.0 - 1e-9;  // the official 0.04 / 0.4 sits on the line, not below it
  std::ostringstream size;
  size << "a model.patch_size = " << config.model.patch_size << " patch spans " << extent << " scene units";
  // Reach is not accuracy: on the large recipe larger radii lost on validation.
  const char* fix_tail =
      " or a smaller model.patch_size, and keep it only if validation improves (on the large recipe radii of one patch came out 4.5 % further "
      "from Blender: model/README.md, \"Radii and patch size\")";
  std::vector<std::string> out;
  if (config.model.world_radius < extent * slack) {
    std::ostringstream w;
    w << "model.world_radius = " << config.model.world_radius << " is smaller than one patch: " << size.str()
      << ", so outer-garment patches over the inner garment can have no world edge to it (`layersnet inspect "
         "DATASET --config FILE` counts them); set model.world_radius >= "
      << extent << fix_tail;
    out.push_back(w.str());
  }
  if (config.model.body_radius < extent * slack) {
    std::ostringstream w;
    w << "model.body_radius = " << config.model.body_radius << " is smaller than one patch: " << size.str()
      << ", so a patch touching the body can find no body vertex within it; set model.body_radius >= " << extent
      << fix_tail;
    out.push_back(w.str());
  }
  return out;
}

std::string to_toml(const Config& config) {
  std::ostringstream out;
  std::string section;
  out << "# Fully resolved LayersNet configuration (every key; defaults included).\n";
  for (const auto& spec : schema().specs()) {
    const auto dot = spec.key.find('.');
    const std::string sec = spec.key.substr(0, dot);
    if (sec != section) {
      out << "\n[" << sec << "]\n";
      section = sec;
    }
    out << spec.key.substr(dot + 1) << " = " << spec.print(config) << "\n";
  }
  return out.str();
}

std::string describe_keys() {
  std::ostringstream out;
  const Config defaults;
  for (const auto& spec : schema().specs())
    out << spec.key << " (" << spec.type << ", default " << spec.print(defaults) << "): " << spec.doc << "\n";
  return out.str();
}

}  // namespace layersnet
