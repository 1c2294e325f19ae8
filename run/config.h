#pragma once
// The resolved configuration of a run: plain structs whose defaults live here, in code.
//
// A TOML file overrides some keys; `include = "base.toml"` (or a list) at the top of a
// file applies the base first, relative to the including file; `--set key=value` applies
// last. Unknown keys, wrong types and out-of-range values are ConfigErrors naming the
// file, line and key, with the closest valid key. `to_toml()` writes the fully resolved
// config (every key) for the run directory and every checkpoint.
#include "model/model_config.h"

#include <cstdint>
#include <map>
#include <stdexcept>
#include <string>
#include <vector>

namespace layersnet {

struct DataConfig {
  std::string dataset = "data/default";  // D-LAYERS-H5 data set folder (dataset.json, stats.h5)
  // Normalisation statistics to train with; empty = <dataset>/stats.h5, which must come from the
  // training split. A named file may come from elsewhere, e.g. the set this one grew from.
  std::string stats;
  int first_frame = 2;    // first input frame t of a sample (t−1 must have a velocity: ≥ 2)
  int max_frames = 0;     // frames per sequence used from first_frame on; 0 = to the end
  // Start each sequence's samples where its ramp into the motion ends (input frame
  // rest_frames + ramp_frames − 1, the frame eval's rollouts start from), not before; files
  // without those attributes keep first_frame.
  bool after_ramp = false;
  int cache_sequences = 8;  // sequences kept in memory by the lazy reader
  // Train on every training sequence and on its mirror image in the plane x = 0
  // (dataset::mirrored): twice the training sequences at no simulation cost. Validation and test
  // are left as they are; the training split's cache holds both (2 × cache_sequences).
  bool mirror = false;
};

struct TrainConfig {
  int epochs = 10;
  int batch_size = 4;                   // samples per update, spread over threads
  double learning_rate = 1e-3;
  std::vector<int> lr_decay_epochs = {2, 4, 6, 8};  // lr ×= lr_gamma after each of these epochs
  double lr_gamma = 0.5;
  int lr_warmup_updates = 0;            // the run's first updates ramp the rate linearly up to it
                                        // (update k at (k + 1) / this); 0 = off (official)
  double adam_beta1 = 0.9;
  double adam_beta2 = 0.999;
  double adam_eps = 1e-8;
  double grad_clip = 0.0;               // global L2 norm; 0 = off (official)
  std::vector<int> rollout_steps = {0, 1, 2, 3, 4, 5, 7, 7, 8, 9};  // max T_n per epoch (last repeats)
  int bptt_steps = 0;                   // self-fed steps the loss's gradient flows back through (the
                                        // last ones before the recorded step; 0 = none, official)
  bool bptt_score_every_step = false;   // with bptt_steps: the loss is the mean over those steps and
                                        // the final one, each against its ground truth (else the
                                        // final step's only)
  double input_noise = 0.0;             // std of Gaussian noise on the input garment positions at t
                                        // (scene units; target stays the truth); 0 = off (official)
  bool rollout_constraints = false;     // project every self-fed frame (training curriculum and
                                        // validation rollouts) onto the cloth constraints, with the
                                        // eval.* limits, as eval.constraints does at rollout time:
                                        // the network then learns from the inputs it will see.
                                        // Off (official)
  double ema_decay = 0.0;               // > 0: keep an exponential moving average of the weights,
                                        // a ← d·a + (1 − d)·θ after every update (starting from the
                                        // run's first weights); validation and best.h5 use the
                                        // average, the updates the weights. 0 = off (official)
  std::string init_from;                // checkpoint or packed model whose weights start a new run
                                        // (fine-tuning); its normalisation statistics replace the
                                        // data set's, Adam starts fresh. Empty = random init
  int64_t seed = 0;
  int threads = 0;                      // 0 = all cores
  int keep_checkpoints = 3;             // last N kept, plus the best by validation error
  int checkpoint_every = 200;           // batches between checkpoints; 0 = epoch ends only
  bool epoch_checkpoints = true;        // a checkpoint at each epoch end (else only at the run's end)
  bool validate = true;                 // one-step error on the val split after each epoch
  bool validate_initial = true;         // and before the first update (best.h5 may be the untrained model)
  int val_samples = 0;                  // val samples used (evenly spaced); 0 = all
  int val_rollout_frames = 20;          // > 0: validate (and pick best.h5) by the mean error of a
                                        // self-fed rollout of up to this many frames per val sequence,
                                        // predicting from the first frame after the file's ramp (else
                                        // from its first sample frame): the one-step error favours
                                        // checkpoints that drift in rollouts. 0 = one-step error
                                        // (official). 20: the default data's frames after the ramp
  // Samples per epoch: the first this many of the epoch's shuffled order, so each epoch draws
  // another subset; 0 = every sample. Keeps an epoch's curriculum and validation at a fixed cost
  // however large the training split grows.
  int64_t epoch_samples = 0;
  int max_steps = 0;                    // stop after this many updates in total (benchmarks); 0 = no limit
  int max_nonfinite_in_row = 10;        // stop after this many skipped updates in a row
  int log_every = 10;                   // steps between progress lines
};

struct EvalConfig {
  std::string split = "test";
  int frames = 36;  // predicted frames per sequence (official test: 36)
  double patch_tether = 0.0;  // rollouts: vertex within this × its patch's rest radius of its
                              // patch mates' centre (eval/tether.h); 0 = off (official, default)
  // Cloth constraints after every predicted frame (run/cloth_constraints.h; not in the paper).
  bool constraints = false;
  double strain_limit = 0.05;      // largest |edge length / rest length − 1| kept
  double fold_limit = 0.0;         // largest shortening of the far-corner distance of two adjacent triangles (0 = none)
  double collision_shell = 0.05;   // scene units kept outside the body and the inner layer (0 = none)
  int constraint_iterations = 8;   // at most this many projection passes per frame
  // Contact friction: a garment vertex within friction_distance of the body (along its normal)
  // keeps (1 − body_friction) of its motion relative to the body, tangentially. 0 = off.
  double body_friction = 0.0;
  double layer_friction = 0.0;     // the same for an outer-layer vertex against the inner layer
  double friction_distance = 0.3;  // scene units
  // Pinned vertices (the file's pin weights) move rigidly with the body under them.
  bool pins = true;
  // Pinned vertices are the data's at every predicted frame, for every method, when the sequence
  // records them (SequenceInfo::pins_recorded): driven like the body, not predicted. Inside the
  // constraints they then replace the rigid carry above.
  bool recorded_pins = false;
  // Factor on the network's correction of its velocity base in rollouts (1 = as trained, 0 = the
  // base alone, e.g. the physics step): a rollout's own frames drift from what training showed it.
  double correction_scale = 1.0;
  // Each predicted frame is the mean of the network's prediction and the mirror image of its
  // prediction on the mirrored scene (dataset::mirror): symmetric under mirrors as the cloth is,
  // for twice the network's (and its velocity base's) time per frame. Off = one prediction.
  bool mirror_average = false;
};

// The physics energy of losses/physics.h on the self-fed steps of the curriculum (not in the
// paper). Off by default (weight 0): it has not yet won on validation.
struct PhysicsConfig {
  double weight = 0.0;           // weight of the energy per garment vertex beside the supervised loss; 0 = off
  int ramp_steps = 0;            // the weight grows linearly from 0 over this many updates (0 = at once)
  bool self_fed_only = true;     // only samples whose input is the model's own (T_n > 0), where the data is silent
  // Terms inside the energy (1 = as Blender's solver weighs them; 0 = term absent).
  double inertia = 1, drag = 1, stretch = 1, bending = 1, gravity = 1, wind = 1, collision_body = 1, collision_layer = 1;
  // The physics step's contact friction (model.physics_step_friction and _distance) as a term of
  // the energy, so the loss holds touching cloth as the step does; 0 = none (needs the physics base).
  double friction = 0;
  double air_damping = 1.0;      // Blender's air_damping the data was made with (its default)
  bool bending_by_height = false;  // losses::PhysicsSettings::bending_by_height
  double body_margin = kBlenderBodyMargin;    // scene units: Blender's push-out distance (generator's settings)
  double layer_margin = kBlenderLayerMargin;  // scene units, cloth-cloth
  // Collision stiffness k_c ramped as HOOD ramps its collision weight: start, then linear to max.
  double collision_stiffness_start = 1e2;
  double collision_stiffness_max = 1e4;
  int collision_ramp_start = 0;  // updates before the ramp begins
  int collision_ramp_steps = 2000;
};

struct Config {
  ModelConfig model;
  LossConfig loss;
  PhysicsConfig physics;
  DataConfig data;
  TrainConfig train;
  EvalConfig eval;
  // Where each key was last set ("file:line:column" or "--set key=value"), for errors that
  // involve several keys; keys left at their defaults are absent.
  std::map<std::string, std::string> set_at;
};

class ConfigError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Refuses settings that pass each key's own range but cannot build a model or a run together
// (ConfigError naming every key involved and where it was set). load_config and
// parse_config_text call it.
void validate_config(const Config& config);

// Defaults, then each file in order (with its includes), then every "key=value".
Config load_config(const std::vector<std::string>& files, const std::vector<std::string>& overrides = {});
// Applies one file (and its includes) on top of `config`.
void apply_config_file(Config& config, const std::string& path);
// A config from TOML text (e.g. the copy inside a checkpoint); `origin` names it in errors.
// Includes are not allowed here: the text must be self-contained (to_toml() output is).
Config parse_config_text(const std::string& toml_text, const std::string& origin);
// A saved config (run config.toml, checkpoint copy) written before a key whose default later
// changed: gives that key its old value. model.decoder_ret_channels: 1 before it existed;
// train.val_rollout_frames: 0.
void apply_saved_config_defaults(Config& config, const std::string& saved_toml_text);
// Applies one "section.key=value" (value in TOML syntax; a bare word is a string).
void apply_override(Config& config, const std::string& assignment);
// The same for a trained model's config: only rollout settings (eval.*) and the physics step's
// conjugate-gradient iterations may change; any other key throws ConfigError (it is fixed by the
// weights and the training).
void apply_rollout_override(Config& config, const std::string& assignment);

// Settings that load but are likely mistakes, one message each naming the keys and the fix
// (`config` and `train` print them as warnings). Empty when none. Today: neighbour radii too
// small for the patch size (rule and measurements: model/README.md, "Radii and patch size").
std::vector<std::string> config_warnings(const Config& config);

// Every key with its value, as TOML that load_config reads back to the same Config.
std::string to_toml(const Config& config);
// Every valid key, with its type and documentation (for `layersnet config --keys`).
std::string describe_keys();

}  // namespace layersnet
