#pragma once
// Normalisation statistics (docs/dlayers-h5.md, "Statistics file"; official stat.h5).
//
// Quantities, all relative to the body root translation r_t of the same frame (translation
// only, no rotation), per frame (dt = 1 frame, as the official diff_pos):
//   position      x_t - r_t                       frames t >= 0
//   velocity      v_t = (x_t - r_t) - (x_{t-1} - r_{t-1})   t >= 1
//   acceleration  a_t = v_t - v_{t-1}             t >= 2
// pooled over every garment AND body vertex of every frame of the training split (the
// official pools both). Unlike the official code, the undefined v_0, a_0, a_1 are left out
// instead of being counted as zeros. root_* hold the same for r_t itself (the official
// trans_* statistics, used to normalise the root motion in the wind token).
//
// stats.h5: attrs format = "dlayers-h5-stats", version = 1, sequences (string array of the
// training ids), units; groups position, velocity, acceleration, root_position,
// root_velocity, root_acceleration, each with datasets mean (3,) f64, std (3,) f64 (a
// standard deviation of 0 is stored as 1) and count () i64 (number of 3-vectors).
#include "dataset/manifest.h"
#include "dataset/sequence.h"

#include <Eigen/Core>

#include <array>
#include <cstdint>
#include <string>
#include <vector>

namespace layersnet::dataset {

struct MeanStd {
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  Eigen::Vector3d std = Eigen::Vector3d::Ones();
  int64_t count = 0;
};

struct NormalisationStats {
  MeanStd position, velocity, acceleration;
  MeanStd root_position, root_velocity, root_acceleration;
  std::vector<std::string> sequences;  // ids it was computed from
};

// The six quantities, by the names stats.h5 groups and checkpoint /stats arrays give them.
struct StatQuantity {
  const char* name;
  MeanStd NormalisationStats::*field;
};
inline constexpr std::array<StatQuantity, 6> kStatQuantities = {{{"position", &NormalisationStats::position},
                                                                  {"velocity", &NormalisationStats::velocity},
                                                                  {"acceleration", &NormalisationStats::acceleration},
                                                                  {"root_position", &NormalisationStats::root_position},
                                                                  {"root_velocity", &NormalisationStats::root_velocity},
                                                                  {"root_acceleration", &NormalisationStats::root_acceleration}}};

// Streaming accumulator (double sums; merged over frames and sequences).
class StatsAccumulator {
 public:
  void add(const Eigen::Vector3d& v);
  MeanStd result() const;  // std 0 -> 1
  int64_t count() const { return n_; }

 private:
  Eigen::Vector3d sum_ = Eigen::Vector3d::Zero(), sum_sq_ = Eigen::Vector3d::Zero();
  int64_t n_ = 0;
};

struct StatsOptions {
  bool include_body = true;  // pool body vertices with garment vertices (official)
  int window_frames = 32;    // frames read at once (bounds memory)
};

// Computes the statistics over the manifest's train split, reading frame windows lazily.
NormalisationStats compute_stats(const DatasetManifest& manifest, const StatsOptions& options = {});
// The same over one sequence in memory (synthetic scenes of tests and benchmarks), as if it
// were the whole training split; `sequences` holds its info.path.
NormalisationStats compute_stats(const Sequence& sequence, const StatsOptions& options = {});

void write_stats(const std::string& path, const NormalisationStats& stats);
// Reads and checks stats.h5; throws DatasetError naming the problem.
NormalisationStats read_stats(const std::string& path);
// For training and evaluation: <root>/stats.h5, or an error that says to run
// `layersnet prepare <root>` when it is missing or (require_training_split) was not computed
// from exactly the manifest's training split, e.g. a stats.h5 copied from a smaller set.
NormalisationStats load_stats_or_explain(const DatasetManifest& manifest, bool require_training_split = true);
// Why `stats` were not computed from exactly `manifest`'s training split; "" when they were.
std::string stats_split_mismatch(const NormalisationStats& stats, const DatasetManifest& manifest);
// For training: `explicit_path` when given (any statistics the user chose; `note` says when they
// do not come from the training split), else load_stats_or_explain(manifest, require_training_split).
NormalisationStats load_training_stats(const DatasetManifest& manifest, const std::string& explicit_path,
                                       bool require_training_split, std::string* note);

}  // namespace layersnet::dataset
