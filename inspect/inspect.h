#pragma once
// What a data set holds (`layersnet inspect`) — sequences per split, frames, body and
// garment vertex/face/patch counts, wind segments, statistics, and how many world edges join
// the outer garment's patches to the inner garments' (the model's only cross-layer attention
// besides the body) at the first frame after the generator's ramp. Reads headers and that
// frame only unless --check, which reads every frame and checks every value against the spec.
// --margins measures the ground truth's collision distances as the collision loss sees them,
// to choose loss.collision_eps and eval.collision_shell from the data, and the ground truth's
// edge strain, to choose eval.strain_limit. --pins carries each sequence's pinned vertices with
// the body as the cloth constraints do (eval.pins), from the first frame after the ramp to the
// last, and measures how far they end up from the ground truth's, beside the pins rigged from the
// body from that frame on (dataset::rig_pins: what `simulate` and eval --rig-pins give). --motion reads every frame
// after the ramp and prints, per split, what the data can teach about dynamics: the body's
// speed and turn rate, the share of frames with wind, and how fast the garments move against
// the body on calm and on windy frames. --physics asks whether the physics energy describes the
// data: the energy of one step is stationary at the frame its simulator would make, so on every
// 10th validation frame after the ramp it compares each term's gradient at Blender's x_{t+1}
// with the inertia's, and fits the term weights that bring the sum closest to zero.
#include "dataset/sample.h"

#include <string>

namespace layersnet::eval {

struct InspectOptions {
  std::string root;      // data-set folder
  bool check = false;    // read every frame and check every value
  bool brief = false;    // totals only
  bool margins = false;  // the training split's ground-truth collision distances and strain
  bool pins = false;     // how closely pinned vertices carried with the body follow the ground truth
  bool motion = false;   // per split: body speed and turn rate, wind share, garment speed with and without wind
  bool physics = false;  // how far Blender's frames are from stationary for the physics energy (losses/physics.h)
};

// How a body moves between two frames (rows: the same vertices, scene units).
struct BodyStep {
  Eigen::RowVector3f shift = Eigen::RowVector3f::Zero();  // centroid displacement, scene units
  double speed = 0;       // m/s of the vertices' centroid
  double turn_rate = 0;   // turns/s about the up axis (absolute), from a least-squares yaw of the
                          // centroid-relative horizontal positions
};
BodyStep body_step(const dataset::Points& before, const dataset::Points& after, char up_axis, float fps, float scale);

// Prints the summary; patches and world edges at `sample_options` (patch size, world radius).
// Throws DatasetError for an unreadable data set.
void inspect_dataset(const InspectOptions& options, const dataset::SampleOptions& sample_options);

}  // namespace layersnet::eval
