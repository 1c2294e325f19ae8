#pragma once
// `layersnet train`: the training loop of a run directory.
//
// Run directory:
//   config.toml                  the fully resolved config (written first; --resume reads it)
//   metrics.jsonl                one JSON object per line: "train" (every log_every updates),
//                                "val" (each epoch), "nonfinite" (skipped update), "resume", "stop"
//   checkpoints/step_XXXXXXXX.h5 after XXXXXXXX batches (every checkpoint_every and at each
//                                epoch end); the last keep_checkpoints are kept
//   best.h5                      the epoch-end checkpoint with the lowest validation error
//
// Per update: batch_size samples in the epoch's shuffled order (GSL mt19937 "shuffle"
// generator), each with T_n ~ U{0..rollout_steps[epoch]} self-fed steps (the "rollout"
// generator; clipped so the rollout starts no earlier than the sequence's first sample frame),
// spread over OpenMP threads. Each sample has its own gradient buffer; the mean is summed in
// sample order, so the update does not depend on which thread ran which sample. Adam with
// lr = learning_rate · lr_gamma^(number of lr_decay_epochs ≤ finished epochs), times
// (k + 1) / lr_warmup_updates for the run's update k < lr_warmup_updates; optional global
// norm clipping. A non-finite loss or gradient skips the update (logged with its samples);
// max_nonfinite_in_row skips in a row stop the run with TrainingStopped.
//
// Exact resume: a checkpoint holds weights, Adam moments and step, epoch, position, and the
// generator states (the shuffle generator as of the start of the epoch, so the order is
// regenerated), so resuming gives bit-identical parameters for the same thread count.
//
// Data parallelism (`mpirun -np R layersnet train`, train/distributed.h): every rank holds the
// model, draws the whole batch's T_n and noise (the generators stay in step) and reads and runs
// only its samples i mod R = rank. Each sample's gradient is summed into the mean in sample
// order across ranks, so R ranks give the bits of one process at the same global batch (when
// each sample's kernels run on the same thread count: 1 per sample when a rank or process has
// more than one sample). Every rank applies the same Adam step. Only rank 0 prints, writes
// metrics and checkpoints; a failure on any rank ends the whole job (MPI_Abort) after printing
// it. A checkpoint resumes under any rank count: its state is that of the global batch.
#include "autodiff/params.h"
#include "run/config.h"

#include <cstdint>
#include <functional>
#include <ostream>
#include <stdexcept>
#include <string>

namespace layersnet {

class TrainingStopped : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct TrainOptions {
  std::string run_dir;
  bool resume = false;          // continue the run in run_dir (its newest checkpoint)
  std::ostream* log = nullptr;  // progress lines; nullptr = std::cout
  // Test hook: called after the batch gradient is summed into params.grads(), before the
  // finiteness check (e.g. to inject a NaN).
  std::function<void(int64_t batch, ad::ParamStore<float>& params)> after_gradients;
};

struct TrainSummary {
  int64_t updates = 0;       // Adam steps applied (whole run, including before a resume)
  int64_t batches = 0;       // batches processed (applied or skipped)
  int64_t skipped = 0;       // skipped in this process
  double first_loss = -1;    // mean total loss of the first batch run by this process
  double last_loss = -1;     // ... of the last applied batch
  double last_val_error = -1, best_val_error = -1;
  double samples_per_second = 0;  // this process, training batches only
  // Seconds of this process's training batches: wall, and per phase (read and optimizer are
  // wall time on the main thread; build and model are summed over the threads).
  double wall_seconds = 0, read_seconds = 0, build_seconds = 0, model_seconds = 0, optimizer_seconds = 0;
  // Summing the batch gradient (wall, main thread): with R > 1 ranks the all-to-all and
  // all-gather of gradient slices (waits for slower ranks included) and the outcome exchange.
  double reduce_seconds = 0;
  int64_t sent_bytes = 0;  // bytes this rank sent to other ranks (0 with one rank)
  std::string last_checkpoint;
};

// Starts (options.resume = false: run_dir must not hold a run) or resumes a run.
TrainSummary train(const Config& config, const TrainOptions& options);

// The config of an existing run (run_dir/config.toml) with `overrides` applied; throws
// ConfigError when the run has no config.toml.
Config run_config(const std::string& run_dir, const std::vector<std::string>& overrides);

// The learning rate of the update that follows updates_done updates, in 0-based epoch `epoch`.
double learning_rate_at(const TrainConfig& train, int epoch, int64_t updates_done);
// The maximum self-fed steps of a 0-based epoch.
int rollout_steps_at(const TrainConfig& train, int epoch);

}  // namespace layersnet
