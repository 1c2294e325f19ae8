#pragma once
// Evaluation of predictors over a split: rollouts, per-frame metrics,
// per-sequence means and the summaries of paper Tables 1–3.
//
// Aggregation (paper: "mean of Euclidean errors for each frame, then average the errors
// across all the frames within each sequence; the final results are the mean of errors from
// all sequences"; official accuracy_l2_rollout):
//   frame     mean over the frame's vertices (all garments, or one garment / layer);
//   sequence  mean over the rollout's frames;
//   summary   mean ± std (population) over sequences.
// Millimetres: scene units / scale · 1000, per sequence (its file's `scale`), before the
// summary. Collision rates are aggregated the same way (per frame -> per sequence -> mean ±
// std), in percent. Layer metrics only over sequences with >= 2 garments. Edge strain
// |length / rest length − 1| (every garment edge once, rest lengths from the file's rest shapes,
// eval::garment_edges): per sequence the mean and 99th percentile over all edges x rollout
// frames (a ratio), summary mean ± std over sequences in percent; also for the ground truth,
// whose strain is the simulator's own.
#include "dataset/manifest.h"
#include "eval/metrics.h"
#include "eval/rollout.h"

#include <array>
#include <limits>
#include <map>
#include <string>
#include <vector>

namespace layersnet::eval {

// Bands of the ground truth's distance from the body (nearest body vertex) at each frame, in
// metres: cloth on the body [0, 0.03), near it [0.03, 0.06), free beyond. 0.03 m is where
// contact friction acts; the split shows whether the error is contact or free-cloth dynamics.
inline constexpr std::array<double, 2> kBodyDistanceBandEdgesM = {0.03, 0.06};
inline constexpr int kBodyDistanceBands = 3;

struct SequenceResult {
  std::string id;
  std::vector<std::string> subsets;        // Table-1 subsets holding the sequence (T, T+W, L, L+W)
  std::vector<std::string> garment_types;  // (G,) layer order
  double scale = 10;                       // scene units per metre
  int first_frame = 0;                     // first predicted frame
  bool after_ramp = false;                 // first_frame from the file's rest_frames + ramp_frames
  // Scene units, means over the rollout's frames:
  double error = 0;
  std::vector<double> error_curve;    // (n,) per rollout frame
  std::vector<double> garment_error;  // (G,)
  double inner_error = 0, outer_error = -1;
  // Per body-distance band (kBodyDistanceBandEdgesM): mean error over the band's vertex-frames
  // (scene units; 0 when empty) and how many vertex-frames fell in it.
  std::array<double, kBodyDistanceBands> band_error{};
  std::array<int64_t, kBodyDistanceBands> band_vertex_frames{};
  // Rates in [0, 1], means over frames (-1: no layers):
  double h_rate = 0, l_rate_outer = -1, l_rate_all = -1, l_rate_outer_near = -1;
  // Edge strain (ratio) over all edges x rollout frames; NaN once a prediction is non-finite:
  double strain_mean = 0, strain_p99 = 0;
  std::vector<double> strain_p99_curve;  // (n,) over each rollout frame's edges
  // Crumple (metrics.h, dihedral_angles_deg), degrees over every interior edge x rollout frame;
  // NaN once a prediction is non-finite:
  double dihedral_mean = 0, dihedral_p99 = 0;
  std::vector<double> dihedral_curve;  // (n,) mean over each rollout frame's interior edges
  // The same rollout cut at the mark (EvalOptions::mark_frames, clamped to n): mean error over
  // the first `mark` frames (scene units) and the mean dihedral angle of frame `mark`.
  int mark = 0;
  double error_to_mark = 0, dihedral_at_mark = 0;
  std::vector<double> step_ms;  // (n,)
  int diverged_at = -1;         // first rollout frame with a non-finite prediction, -1 = none
  // Under EvalOptions::wind_scale != 1, for a predictor that sees the scaled wind: the mean
  // distance (scene units, over the rollout's frames and vertices) between this rollout and the
  // same predictor's under the data's wind, i.e. how far the wind change moves its cloth, whatever
  // the direction. -1 = not measured.
  double wind_moved = -1;
  // Under EvalOptions::wind_twins as well, for the same predictors (NaN = not measured), in scene
  // units: twin_moved = mean distance between the data and Blender's twin under the scaled wind
  // (how far the wind moves Blender's cloth); twin_moved_in_window = the same with the twin moved
  // by the two's difference at the input frame (how far it moves it within the rollout's window,
  // from the state the rollouts start from); wind_error_rise = this rollout's error minus that of
  // the rollout under the data's wind; wind_share = wind_share() of the two rollouts against the
  // twin moved so (a ratio).
  double twin_moved = std::numeric_limits<double>::quiet_NaN();
  double twin_moved_in_window = std::numeric_limits<double>::quiet_NaN();
  double wind_error_rise = std::numeric_limits<double>::quiet_NaN();
  double wind_share = std::numeric_limits<double>::quiet_NaN();
  double mm() const { return 1000.0 / scale; }  // millimetres per scene unit
};

struct MethodResult {
  std::string name;
  std::string kind;  // "model", "baseline", "ground truth"
  std::string checkpoint;  // models only
  std::string checkpoint_sha256;  // models only: the file's SHA-256, hex
  // Run with the cloth constraints, contact friction and pins after every predicted frame.
  bool post_processed = false;
  std::vector<SequenceResult> sequences;
  double ms_per_frame_1thread = -1, ms_per_frame_2threads = -1;  // median, -1 = not measured
};

struct EvalOptions {
  std::string split = "test";
  int frames = 36;          // predicted frames per sequence (clamped to the sequence)
  // Rollout start. After the ramp: per sequence, the first predicted frame is the file's
  // rest_frames + ramp_frames (the body's ramp from the rest pose into the clip is not
  // motion to predict); start_frame for files without them. Otherwise t0 = start_frame.
  bool start_after_ramp = true;
  int start_frame = 2;      // input frame t0 of the first prediction (>= 2)
  int max_sequences = 0;    // 0 = every sequence of the split
  // Sequences of the split to evaluate, each an id or an inclusive range FIRST..LAST of ids in
  // string order ("00048..00083"); empty = all. Applied before max_sequences.
  std::vector<std::string> sequences;
  // Long rollouts are also summarised at this many frames (the official test length), so a
  // rollout over every moving frame still gives the 36-frame figures.
  int mark_frames = 36;
  double max_body_distance_m = 0.5;   // H-collision distance limit in metres (official 5.0 units at scale 10)
  double max_layer_distance_m = 0.05; // "near" L-collision distance limit in metres
  // Factor on the data's wind strengths as every predictor sees them (1 = the data's); the
  // ground truth the rollouts are scored against is unchanged. With 0 or 2 it measures how much
  // a model responds to the wind.
  double wind_scale = 1.0;
  // Folder of Blender's re-simulations of the evaluated sequences with the wind x wind_scale and
  // nothing else changed (scripts/predictability.sh calm-wind twins; a file of the same name per
  // sequence). Empty = none. Needs wind_scale != 1; its scene.json's wind_scale must match.
  std::string wind_twins;
  // Evaluate the mirror images of the split's sequences (dataset::mirror, x → −x) instead: every
  // predictor and the ground truth see the image. The simulator and the model-free baselines are
  // symmetric under it, so a model that learned the cloth rather than its data's handedness is as
  // close on the images as on the files. Not with wind_twins.
  bool mirror = false;
  // Every method's pinned vertices are the data's each frame (eval::rollout's recorded_pins).
  bool recorded_pins = false;
  // Every method but the ground truth sees the pins rigged from the body (dataset::rig_pins from
  // the rollout's input frame), as `simulate` rigs a user's scene, instead of the data's; the
  // error is still against the data.
  bool rig_pins = false;
};

// Table-1 subsets of a data set: id -> subset names, from dataset.json "subsets" (written by
// `layersnet generate`); empty when the file has none.
std::map<std::string, std::vector<std::string>> read_subsets(const std::string& dataset_root);

// Blender's seconds per frame recorded at generation (root attribute q_blender_s_per_frame),
// or -1 when the file has none.
double blender_seconds_per_frame(const std::string& sequence_path);

// The ids of `split_ids` that `selection` names (EvalOptions::sequences), in split order.
// Throws, naming `where` (the manifest), the split and the entry, for an entry that matches none.
std::vector<std::string> select_sequences(const std::vector<std::string>& split_ids,
                                          const std::vector<std::string>& selection, const std::string& split,
                                          const std::string& where);

// The input frame t0 of a sequence's rollouts under `options` (see EvalOptions), and whether
// it came from the file's ramp attributes.
struct RolloutStart {
  int input_frame = 2;
  bool after_ramp = false;
};
RolloutStart rollout_start(const std::string& sequence_path, const EvalOptions& options);

// The share of Blender's wind movement that a model reproduces. Per frame k and vertex v, the
// model moves by m = model_data_wind - model_scaled when its wind goes from the scaled one to the
// data's, and Blender's cloth by g = truth - twin; the share is sum m.g / sum g.g (1 = all of it,
// 0 = none or across it, < 0 = against it). Frame lists of equal length, points (N, 3) each.
// NaN when Blender's cloth does not move. evaluate() passes the twin moved by its offset from the
// data at the input frame, since both model rollouts start from the data's state there.
double wind_share(const std::vector<Points>& model_scaled, const std::vector<Points>& model_data_wind,
                  const std::vector<Points>& twin, const std::vector<Points>& truth);

// Predicts every sequence with every predictor. The same frames, metrics and sequences for all.
// progress: print one line per sequence and method to stdout.
std::vector<MethodResult> evaluate(const dataset::DatasetManifest& manifest, std::vector<Predictor*> predictors,
                                   const EvalOptions& options, bool progress = false);

// Metrics of one rollout against the sequence's ground truth.
// mark_frames: see EvalOptions::mark_frames.
SequenceResult score_rollout(const dataset::Sequence& seq, const Rollout& r, const CollisionOptions& options,
                             int mark_frames = 36);

// Ground-truth "predictor": returns the data's next frame (its collision rates are the floor).
class GroundTruth : public Predictor {
 public:
  std::string name() const override { return "ground truth"; }
  Points step(const dataset::Sequence& seq, int t, const Points&, const Points&, const Points&) override {
    return garments_at(seq, t + 1);
  }
};

// Another simulator's recorded frames: for the sequence being evaluated, the file of the same
// name in `folder` (its garments must match in number, layer order and vertex count, and it
// must hold at least as many frames); step() returns its frame t + 1 whatever the inputs. It
// scores a re-simulation, a nudged twin or another solver's output with the models' metrics.
class Replay : public Predictor {
 public:
  Replay(std::string name, std::string folder) : name_(std::move(name)), folder_(std::move(folder)) {}
  std::string name() const override { return name_; }
  // Reads <folder>/<file name of seq>; throws naming both files when they do not match.
  void begin(const dataset::Sequence& seq) override;
  Points step(const dataset::Sequence& seq, int t, const Points&, const Points&, const Points&) override;

 private:
  std::string name_, folder_;
  std::string loaded_;  // path of recorded_
  dataset::Sequence recorded_;
};

// Median wall time per predicted frame, from a rollout of `frames` frames of `seq` run with
// `threads` OpenMP threads (the previous thread count is restored).
double median_ms_per_frame(Predictor& predictor, const dataset::Sequence& seq, int t0, int frames, int threads);

// ---- summaries (millimetres and percent)
struct Summary {
  MeanStd error_mm, inner_mm, outer_mm;
  MeanStd h_percent, l_outer_percent, l_all_percent, l_near_percent;
  MeanStd strain_mean_percent, strain_p99_percent;  // edge strain × 100
  MeanStd wind_moved_mm;                            // over the sequences where it was measured
  MeanStd twin_moved_mm, twin_moved_in_window_mm, wind_error_rise_mm, wind_share;  // under EvalOptions::wind_twins
  std::map<std::string, MeanStd> by_type_mm;    // garment type -> over sequences holding it
  std::map<std::string, MeanStd> by_subset_mm;  // T, T+W, L, L+W
  std::vector<double> curve_mm;                 // mean over sequences per rollout frame
  std::vector<double> strain_p99_curve_percent; // the same of the per-frame strain p99
  MeanStd dihedral_mean_deg, dihedral_p99_deg;   // crumple, over sequences
  std::vector<double> dihedral_curve_deg;        // mean over sequences per rollout frame
  // At the mark (EvalOptions::mark_frames) and at each rollout's last frame:
  MeanStd error_to_mark_mm, dihedral_at_mark_deg, dihedral_end_deg;
  int mark = 0;                                  // the shortest sequence's mark
  // Per body-distance band: error pooled over every vertex-frame of every sequence in the band
  // (mm; NaN when none) and the band's share of all vertex-frames.
  std::array<double, kBodyDistanceBands> band_mm{}, band_share{};
  // The same pooled into two: on or near the body (under the last band edge, 6 cm) and free
  // cloth beyond it, where a learned simulator has to earn its keep.
  double near_body_mm = 0, free_cloth_mm = 0, free_share = 0;
  double median_step_ms = 0;                    // over every step of every sequence
  int diverged = 0;  // sequences with a non-finite prediction: left out of every number above
};
Summary summarise(const MethodResult& method);

// A model against one baseline run with the same post-processing: the ratio of their mean errors
// (the headline form) and the ratio per sequence, whose spread the mean hides.
struct Comparison {
  std::string model, baseline;
  bool post_processed = false;
  bool best_baseline = false;    // the baseline with the lowest mean error under this post-processing
  double ratio_of_means = 0;     // model error / baseline error, both mean over sequences (mm)
  double free_ratio_of_means = 0;  // the same over free cloth (Summary::free_cloth_mm)
  std::vector<std::string> ids;  // sequences where both are finite
  std::vector<double> ratios;    // per sequence, in ids order
  double mean_ratio = 0, median_ratio = 0, worst_ratio = 0;
  std::string worst_id;
  int skipped = 0;               // sequences left out: one of the two diverged
};
// Every model result against every baseline result with the same post_processed flag, in
// method order. Empty when there is no pair.
std::vector<Comparison> compare_with_baselines(const std::vector<MethodResult>& methods);

}  // namespace layersnet::eval
