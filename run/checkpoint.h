#pragma once
// Training checkpoints in HDF5, readable by h5py:
//
//   /                 attrs format = "layersnet-checkpoint", version = 1, program = "layersnet X.Y.Z",
//                     checksum = "fnv1a64:<16 hex digits>" over everything below (absent in files
//                     of older program versions, which load unchecked)
//   /config           attr  toml: the fully resolved configuration (text)
//   /weights/<name>   float32 (rows, cols), one per parameter, dotted names
//                     ("encoder.layers.0.attn.q_proj.weight")
//   /adam/m/<name>, /adam/v/<name>   float32 (rows, cols): Adam's moments; attr step. Absent
//                     in a packed model (weights only: what `layersnet pack` ships), which
//                     runs, evaluates and fine-tunes but cannot resume a run
//   /ema/<name>       float32 (rows, cols): the moving average of the weights
//                     (train.ema_decay > 0), beside the weights the updates change; absent
//                     otherwise and in best.h5, whose /weights are then the average
//   /state            attrs epoch, position (next sample index in the epoch's order),
//                     global_step, best_val_error, nonfinite_in_row
//   /state/rng/<name> uint8 (bytes,): the raw state of each named GSL generator
//   /stats/<name>     float64 arrays: the normalisation statistics the run used
//
// Writes go to "<path>.tmp", are flushed and fsync'ed, then renamed over <path>: a crash at
// any moment leaves either the old or the new checkpoint, never a torn one.
#include "autodiff/params.h"
#include "run/config.h"

#include <cstdint>
#include <map>
#include <stdexcept>
#include <string>
#include <vector>

namespace layersnet {

inline constexpr const char* kCheckpointFormat = "layersnet-checkpoint";
inline constexpr int kCheckpointVersion = 1;

class CheckpointError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct TrainingState {
  int64_t epoch = 0;        // 0-based epoch in progress
  int64_t position = 0;     // samples of this epoch already consumed
  int64_t global_step = 0;  // updates applied (Adam's t)
  double best_val_error = -1;  // < 0: none yet
  int64_t nonfinite_in_row = 0;
  std::map<std::string, std::vector<uint8_t>> rng;  // GSL generator states by name
};

struct Checkpoint {
  bool has_optimizer = true;  // false: a packed model (no Adam moments; moments read as 0)
  std::string config_toml;
  TrainingState state;
  std::map<std::string, std::vector<double>> stats;
  std::vector<float> ema;  // the weights' moving average, laid out as the parameters; empty: none
};

// Writes params (values, and Adam moments when checkpoint.has_optimizer) and `checkpoint`
// atomically to `path`.
void write_checkpoint(const std::string& path, const ad::ParamStore<float>& params, const Checkpoint& checkpoint);

// Reads `path` into `params` (whose layout must match: same names and shapes; every
// difference is listed in the error) and returns the rest. Refuses other formats and
// versions, truncated or corrupted files, content that does not match its checksum, and
// values no training writes (non-finite weights, moments or statistics, a negative Adam second
// moment, a statistics std <= 0), with a message naming the file.
Checkpoint read_checkpoint(const std::string& path, ad::ParamStore<float>& params);

// Only the config text of a checkpoint (to rebuild the model before reading weights).
std::string read_checkpoint_config(const std::string& path);

// A trained model ready to run: the checkpoint's own config, its parameters laid out by
// model::register_params for that config, and the rest of the checkpoint.
struct LoadedModel {
  Config config;
  ad::ParamStore<float> params;
  Checkpoint checkpoint;
};
LoadedModel load_model(const std::string& checkpoint_path);

// True when a and b agree in everything but [loss], [physics], [data], [train] and [eval]: the
// settings that do not change what a weight means.
bool same_model_section(const Config& a, const Config& b);

// The weights of a checkpoint trained with another [model] config, copied by name into `params`
// (train.init_from): the checkpoint is read whole into its own model's layout (checksum and all),
// then every tensor goes to the tensor of the same name. A tensor this model has and the
// checkpoint lacks starts at zero and is named in `added`, so an added input weight (e.g.
// decoder.local.weight) leaves the model computing what the checkpoint's did; a tensor the
// checkpoint has and this model lacks, or one whose shape differs, is a CheckpointError naming it.
// Adam moments are zeroed.
struct WeightsByName {
  Checkpoint checkpoint;           // its state and statistics
  Config config;                   // the config it was trained with
  std::vector<std::string> added;  // this model's tensors the checkpoint lacks (set to zero)
};
WeightsByName read_weights_by_name(const std::string& path, ad::ParamStore<float>& params);

// The element-wise mean of the weights of `checkpoint_paths` (at least one), for averaging
// the last epochs of one run: the config, statistics and state are the first file's, without
// optimizer state. Throws CheckpointError naming the file when its model settings or its
// normalisation statistics differ from the first's (their weights would not mean the same).
LoadedModel average_models(const std::vector<std::string>& checkpoint_paths);

}  // namespace layersnet
