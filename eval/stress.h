#pragma once
// Stability at the extremes: long rollouts of a model under conditions
// beyond its training data, and float32 against float64 on the same checkpoint.
//
// Stress scene. A sequence of F frames built in memory from a real one (T frames):
//   time      stress frame t plays source time u(t) = f0 + pingpong(s·t) in [f0, T−1]
//             (forward, then backward, ...), linearly interpolated between source frames, so
//             every body velocity is s× the data's (s = speed) and the motion never runs out.
//             f0 (`first`) skips the generator's rest and T-pose ramp (frames where the body
//             swings from the T-pose into the clip at up to 0.8 m/frame — an initialisation
//             artefact, not body motion; replaying it backwards every loop would test the
//             ramp, not the animation);
//   body      vertices and root translation at u(t);
//   garments  at u(t) too: frames 0..2 are the rollout's initial state (consistent with the
//             resampled body); later frames are placeholders that only fill the sample's
//             unused target slot (ModelPredictor::step) — they are not ground truth;
//   wind      strength S >= 0: constant strength S along the source's first windy segment's
//             direction (+x when the source has none); S < 0: the source's own wind at u(t).
//
// Bound on every predicted vertex (scene units). A worn garment touches the body (or the
// layer under it, which touches the body), so its nearest vertex is within c_g of the body,
// c_g = the garment's smallest vertex-to-body distance at frame 0 (the layer gap). Every
// other vertex lies within the garment's Euclidean extent of that one, and the extent of
// real cloth stays below its rest graph diameter D_g (longest shortest edge path, rest
// lengths): the generated data reach at most 0.89 D_g in any frame of any garment
// (scripts/garment_extent.py; single short edges do stretch up to 6x, whole paths do not).
// With kStretchAllowance = 1.2 for headroom, for every vertex v of garment g at every frame:
//   dist(v, body_t) <= B_g = c_g + kStretchAllowance · D_g.
// dist is to the nearest body VERTEX (an upper bound of the distance to the body surface).
// It holds for cloth blown straight out by wind, and fails only for cloth that came off
// the body or spread 35 % beyond anything the simulator produced — an unstable rollout.
//
// Strain limit. Torn or inflated cloth can stay within the bound (patches drifting apart
// while the garment hangs on the body), so every frame's p99 over the garment edges of the
// strain |length / rest length − 1| (edge_strains) must also stay <= kStrainAllowance × the
// data set's worst per-frame p99 (data_set_strain: every sequence after its ramp). The p99,
// not the max: single short edges of real cloth stretch up to 6x.
// data/default (12 sequences, frames after the ramp): worst per-frame p99 0.885 (00007;
// 0.075–0.885 per sequence), worst max 5.21. Factor 2 (limit 1.77 there): a model's first
// step from the ground truth adds only 0.03–0.15 to the data's p99 (quick model), while a
// garment stretched 3x everywhere (strain 2) must fail, so the factor stays below 2 / 0.885.
#include "autodiff/params.h"
#include "dataset/garments.h"
#include "dataset/manifest.h"
#include "dataset/sequence.h"
#include "dataset/stats.h"
#include "eval/rollout.h"
#include "run/config.h"

#include <string>
#include <vector>

namespace layersnet::eval {

inline constexpr double kStretchAllowance = 1.2;  // garment extent / D_g allowed (data: <= 0.89)
inline constexpr double kStrainAllowance = 2.0;   // strain p99 limit / the data's worst p99 (see above)

struct StressScene {
  int frames = 600;             // F: frames of the built sequence (D-LAYERS' longest: 600)
  double speed = 1.0;           // s: body and root velocity factor (> 0)
  double wind_strength = -1.0;  // S >= 0: constant wind of this strength; < 0: the source's wind
  int first = 0;                // f0: first source frame played (0 <= f0 <= T − 2)
};

// Largest body vertex speed (scene units per frame) of the stress sequence with this speed
// factor over `frames` frames (computed without building it).
double body_top_speed(const dataset::Sequence& source, int first, double speed, int frames);
// The speed factor s whose stress body's top speed is `multiple` × the data's (s = 1) top
// speed over the same frames. Body velocity × s everywhere does not give top speed × s: one
// stress frame then spans s source frames, averaging their velocities. The smallest s on a
// grid over [multiple, 4·multiple] (step 0.05·multiple) that reaches it; when none does (a
// short source: any two of its poses are close), the grid's fastest — callers report the
// top speed reached.
double speed_factor_for_top_speed(const dataset::Sequence& source, int first, double multiple, int frames);

// First frame after the generator's rest and ramp (SequenceInfo::settled_frame, from the root
// attributes rest_frames + ramp_frames that `layersnet generate` writes); `missing` when it is 0.
int settled_frame(const std::string& sequence_path, int missing = 0);

// Builds the stress sequence (see above). Throws std::invalid_argument for frames < 4,
// speed <= 0 or f0 outside [0, T − 2], naming the source file.
dataset::Sequence make_stress_sequence(const dataset::Sequence& source, const StressScene& scene);

// Per garment (G,): graph diameter D_g of the rest mesh (the file's /rest template, else
// frame 0), scene units, via Dijkstra from every vertex (N_g² log N_g: fine for N_g ~ 10³).
std::vector<double> garment_graph_diameters(const dataset::Sequence& seq);
// The same from the edges already listed (garment_edges(seq)).
using dataset::GarmentEdges;
std::vector<double> garment_graph_diameters(const dataset::Sequence& seq, const GarmentEdges& edges);
// Per garment (G,): B_g = c_g + kStretchAllowance · D_g (see above), from frame 0.
std::vector<double> garment_distance_bounds(const dataset::Sequence& seq);
// The same from diameters already computed (garment_graph_diameters(seq)).
std::vector<double> garment_distance_bounds(const dataset::Sequence& seq, const std::vector<double>& diameters);

// Per garment, its vertices' distances to their nearest body vertex at frame t of `seq`:
// the largest (what the bound limits) and the smallest (grows when cloth comes off the body).
struct GarmentBodyDistance {
  double farthest = 0;
  double nearest = 0;
};
// x (N, 3) world in layer order -> (G,), scene units; NaN if the garment's rows hold a NaN.
std::vector<GarmentBodyDistance> garment_body_distances(const dataset::Sequence& seq, int t, const Points& x);

// Every mesh edge once, as rows of the layer-ordered garment points, garment by garment, with
// its rest length (rest_garments: the file's /rest template, else frame 0).
GarmentEdges garment_edges(const dataset::Sequence& seq);
// max over edges of length / rest length (edges of zero rest length skipped).
double max_edge_stretch(const GarmentEdges& edges, const Points& x);
using dataset::edge_strains;

// Edge strain of one frame (p99 and max over edge_strains), or the worst of many frames.
struct StrainExtremes {
  double p99 = 0;
  double max = 0;
};
StrainExtremes frame_strain(const GarmentEdges& edges, const Points& x);
// The ground truth's own worst per-frame strain over frames first..T−1 of `seq`.
StrainExtremes data_strain(const dataset::Sequence& seq, int first);
// The same over every sequence of a data set, each from its settled_frame (the strain
// limit's basis: kStrainAllowance × p99).
StrainExtremes data_set_strain(const dataset::DatasetManifest& manifest);

// The data's own max over frames first..T−1 and garments of dist / B_g (B_g from frame
// `first`, as a stress scene starting there uses): how much room the bound leaves real cloth.
double data_bound_ratio(const dataset::Sequence& source, int first);

struct StressResult {
  std::string label;            // e.g. "wind 2000", "speed 5x"
  StressScene scene;
  int frames = 0;               // predicted frames
  bool finite = true;
  int first_bad_frame = -1;     // first rollout index that is non-finite or out of bound; -1 none
  double max_bound_ratio = 0;   // max over frames and garments of dist / B_g (pass: <= 1)
  double max_diameter_ratio = 0;  // max over frames and garments of dist / D_g
  double max_vertex_speed = 0;  // garment vertices, scene units per frame
  double max_body_speed = 0;    // body vertices in the stress sequence, scene units per frame
  double ms_per_frame = 0;      // median prediction time
  std::vector<double> bounds;   // (G,) B_g
  // Per predicted frame (frames,): what went wrong when a run fails.
  std::vector<double> bound_ratio_per_frame;   // max over garments of dist / B_g
  std::vector<double> vertex_speed_per_frame;  // max garment vertex speed, units per frame
  std::vector<double> nearest_per_frame;       // max over garments of the nearest vertex's distance
                                               // to the body, units (cloth leaving the body)
  std::vector<double> edge_stretch_per_frame;  // max edge length / rest length (cloth stretching)
  double strain_limit = 0;      // pass: every frame's strain p99 <= this
  double max_strain_p99 = 0;    // max over frames of the strain p99
  double max_strain = 0;        // max over frames and edges of the strain
  int first_torn_frame = -1;    // first rollout index whose strain p99 > strain_limit; -1 none
  std::vector<double> strain_p99_per_frame, strain_max_per_frame;  // edge strain |l / l0 − 1|
  bool within_bound() const { return max_bound_ratio <= 1; }
  bool within_strain() const { return first_torn_frame < 0; }
  bool passed() const { return finite && first_bad_frame < 0; }
};

// Rolls `predictor` over make_stress_sequence(source, scene) from input frame 2 to the end;
// first_bad_frame is the first frame non-finite, out of bound or over `strain_limit`.
StressResult stress_rollout(Predictor& predictor, const dataset::Sequence& source, const StressScene& scene,
                            const std::string& label, double strain_limit);

// The model predictor in float64: the same checkpoint's parameters converted to double, the
// same samples (built in float32 by the data layer, as for the float model) cast with
// model::cast_input; only the network's arithmetic differs.
class DoubleModelPredictor : public NetworkPredictor<double> {
 public:
  DoubleModelPredictor(Config config, const ad::ParamStore<float>& params, dataset::NormalisationStats stats);
  std::string name() const override { return "float64"; }
};

// float32 vs float64 rollouts of one checkpoint over `frames` frames of the stress sequence
// with speed 1, the source's wind and f0 = first. Bound: the largest per-frame mean divergence must stay
// below the float model's own mean error against the ground truth on the source sequence
// (all its frames from input frame 2): rounding then changes the rollout by less than the
// model is wrong anyway.
struct PrecisionResult {
  int frames = 0;
  std::vector<double> max_divergence, mean_divergence;  // (frames,) per-vertex max / mean, scene units
  double model_error = 0;   // float model vs ground truth on the source, mean per vertex, scene units
  double mm_per_unit = 100; // 1000 / scale
  double ms_float = 0, ms_double = 0;  // median per frame
  bool finite = true;
  double worst_mean() const;
  double worst_max() const;
  bool passed() const { return finite && worst_mean() < model_error; }
};
PrecisionResult compare_precision(const Config& config, const ad::ParamStore<float>& params,
                                  const dataset::NormalisationStats& stats, const dataset::Sequence& source, int frames,
                                  int first = 0);

}  // namespace layersnet::eval
