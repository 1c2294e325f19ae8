#pragma once
// The samples of one data-set split as the training loop needs them: a fixed list of
// (sequence, t) that the loop shuffles itself (GSL generator, checkpointed), frame windows
// read on demand, and samples built from a window whose garment frames may have been
// replaced by the model's own predictions (the paper's noisy-rollout curriculum).
//
// Thread use: everything that touches files (read_window: HDF5 is not thread-safe, LRU of
// open files, structure cache) runs on the calling thread; build() is pure and may run on
// any thread with its own Window.
#include "dataset/manifest.h"
#include "dataset/sample.h"
#include "dataset/sequence.h"
#include "dataset/stats.h"
#include "run/cloth_constraints.h"
#include "run/config.h"
#include "run/frame_selection.h"

#include <cstdint>
#include <list>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace layersnet {

struct SampleRef {
  int32_t sequence = 0;  // index into TrainData::ids()
  int32_t t = 0;         // input frame (predicts t+1)
};

// Frames [first, first+count) of one sequence with its static parts; garments may be
// overwritten (world coordinates) by predictions.
struct Window {
  std::string sequence_id;
  std::shared_ptr<const dataset::SequenceInfo> info;
  std::shared_ptr<const dataset::SequenceStructure> structure;
  dataset::FrameWindow frames;
  // (N·3,) world offsets (scene units) added to the garments of the sample's input frame t
  // after the self-fed steps (train.input_noise); empty = none.
  std::vector<float> input_noise;
  // Sets garment positions of frame f (world, scene units) from root-relative predictions
  // x̃ (N, 3) row-major: x = x̃ + r_f.
  void set_garments_relative(int f, const float* relative);
  // Adds input_noise to the garments of frame f.
  void add_input_noise(int f);
  // Cloth constraints of the sequence (train.rollout_constraints), else null.
  std::shared_ptr<const ClothConstraints> constraints;
  // Sets frame f's garments from root-relative predictions as set_garments_relative does, then
  // projects them onto `constraints` (when set) against the body of frame f.
  void feed_back(int f, const float* relative);
};

class TrainData {
 public:
  // Opens each sequence of `split` once for its frame count, and keeps the first
  // data.cache_sequences of them open with their structures. Sample frames follow
  // config.data (first_frame .. first_frame + max_frames - 2). With data.mirror the training
  // split also holds each file's mirror image (dataset::mirrored) as sequence index n + i of file
  // i, n files, with the same sample frames; the cache then holds 2 × data.cache_sequences.
  TrainData(const dataset::DatasetManifest& manifest, const std::string& split, const dataset::NormalisationStats& stats,
            const Config& config);

  const std::vector<SampleRef>& samples() const { return samples_; }
  int64_t num_samples() const { return static_cast<int64_t>(samples_.size()); }
  // Sequence names: the file's id, and "<id> mirrored" for a mirror image.
  const std::vector<std::string>& ids() const { return ids_; }
  const std::string& split() const { return split_; }
  // First sample frame of a sequence: a rollout may start no earlier.
  int first_t(int sequence) const { return first_t_.at(static_cast<std::size_t>(sequence)); }
  // Input frame of a validation rollout: the one predicting the first frame after the file's rest
  // pose and ramp (SequenceInfo::settled_frame; `layersnet eval` starts there too) when that is a
  // sample frame, else first_t: the ramp into the motion is set-up, not motion to predict.
  int rollout_start(int sequence) const { return rollout_start_.at(static_cast<std::size_t>(sequence)); }
  // Garment vertices of a sequence, known without reading its frames (a rank draws the input
  // noise of samples other ranks read).
  int garment_vertices(int sequence) const { return garment_vertices_.at(static_cast<std::size_t>(sequence)); }

  // Frames [t_first - 2, t_last + 1] of a sequence (calling thread only).
  Window read_window(int sequence, int t_first, int t_last);
  // The training sample at t from the window (any thread).
  dataset::TrainingSample build(const Window& window, int t) const;
  const dataset::NormalisationStats& stats() const { return stats_; }

  // What read_window has read so far: the bound on memory and I/O (bench dataset_memory).
  struct Reads {
    int64_t windows = 0;
    int64_t bytes = 0;  // positions, as float32 in memory
    int64_t files_opened = 0;  // kept open: the constructor's first data.cache_sequences, then reopens
  };
  const Reads& reads() const { return reads_; }

 private:
  struct OpenFile {
    int sequence;
    std::shared_ptr<dataset::SequenceFile> file;
    std::shared_ptr<const dataset::SequenceInfo> info;
    std::shared_ptr<const ClothConstraints> constraints;  // train.rollout_constraints only
    std::shared_ptr<const dataset::SequenceStructure> structure;
  };
  OpenFile& open(int sequence);
  // Puts an opened file at the front of the LRU with what a window needs of it besides frames.
  OpenFile& keep_open(int sequence, std::shared_ptr<dataset::SequenceFile> file);

  dataset::DatasetManifest manifest_;
  std::string split_;
  dataset::NormalisationStats stats_;
  dataset::SampleOptions sample_options_;
  ModelConfig model_;  // what the velocity base adds to each sample
  int max_open_files_;
  std::optional<EvalConfig> constraint_settings_;  // train.rollout_constraints only
  std::vector<std::string> file_ids_;  // the split's files (n)
  std::vector<std::string> ids_;       // sequences: the n files, then their n mirror images with data.mirror
  bool mirrored(int sequence) const { return sequence >= static_cast<int>(file_ids_.size()); }
  std::vector<int> first_t_;
  std::vector<int> rollout_start_;
  std::vector<int> garment_vertices_;
  std::vector<SampleRef> samples_;
  std::list<OpenFile> files_;  // LRU, front = most recent; each holds its sequence's structure
  float patch_size_;
  Reads reads_;
};

}  // namespace layersnet
