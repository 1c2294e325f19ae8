#pragma once
// Files of a run directory (see trainer.h): checkpoint names, listing and pruning, atomic
// text writes, and the statistics as they are stored inside a checkpoint.
#include "dataset/stats.h"

#include <cstdint>
#include <map>
#include <string>
#include <vector>

namespace layersnet {

// <run>/checkpoints/step_<batches, 8 digits>.h5
std::string checkpoint_path(const std::string& run_dir, int64_t batches);
// Existing checkpoints, oldest first (ignores *.tmp left by a kill).
std::vector<std::string> list_checkpoints(const std::string& run_dir);
// <run>/best.h5: the checkpoint of the best validation error so far.
std::string best_checkpoint_path(const std::string& run_dir);
// The checkpoint that stands for a run: best.h5, else the newest checkpoint. Throws
// std::runtime_error when the folder has neither.
std::string run_checkpoint(const std::string& run_dir);
// Deletes all but the newest `keep`, and stale *.tmp files.
void prune_checkpoints(const std::string& run_dir, int keep);
// True when run_dir has a config.toml, metrics or checkpoints (a run was started there).
bool holds_run(const std::string& run_dir);

// Exclusive hold of a run directory for one training process: an flock on <run>/lock, which
// the kernel releases when the process ends however it ends (kill -9 included), so a stale
// lock never blocks a resume. The file names the holder (pid, host, start time) for the error
// the next process gets.
class RunLock {
 public:
  // Throws std::runtime_error naming the holder when another process holds the lock.
  explicit RunLock(const std::string& run_dir);
  ~RunLock();
  RunLock(const RunLock&) = delete;
  RunLock& operator=(const RunLock&) = delete;

 private:
  int fd_ = -1;
};

// NormalisationStats <-> checkpoint /stats arrays ("position.mean", "position.std", ...;
// reading also accepts "position_mean", and a missing count leaves it 0).
std::map<std::string, std::vector<double>> stats_to_arrays(const dataset::NormalisationStats& stats);
// Throws std::runtime_error naming `origin` and the missing array.
dataset::NormalisationStats stats_from_arrays(const std::map<std::string, std::vector<double>>& arrays,
                                              const std::string& origin);

}  // namespace layersnet
