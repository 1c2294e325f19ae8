#pragma once
// Pinned cloth carried rigidly with the body region its pins enclose. The data's simulator skins
// pinned vertices (a waistband, a top edge) to the torso's bones, which the body surface next to
// them does not follow (a thigh's skin weights pull the surface at the hips). A rigid fit of the
// body inside the pinned loop follows those bones closely without knowing the rig.
//
// One road for two jobs: the post-processing's pin step, which carries the pins from each frame to
// the next (run/cloth_constraints.h), and the rig of a scene that records none (rig_pins below:
// `simulate`, and eval --rig-pins to measure it on data).
#include "dataset/sequence.h"

#include <Eigen/Core>

#include <cstdint>
#include <vector>

namespace layersnet::dataset {

// y ≈ rotation · x + translation.
struct RigidMotion {
  Eigen::Matrix3d rotation = Eigen::Matrix3d::Identity();
  Eigen::Vector3d translation = Eigen::Vector3d::Zero();
};

// The least-squares rigid motion (Kabsch, no reflection) carrying rows `rows` of `from` onto the
// same rows of `to`; both (B, 3). In double for the 3×3 SVD.
RigidMotion fit_rigid_motion(const Eigen::Ref<const Points>& from, const Eigen::Ref<const Points>& to,
                             const std::vector<int32_t>& rows);

// One garment's pinned rows and the body vertices whose rigid motion carries them.
struct PinGroup {
  int32_t garment = 0;            // its index in SequenceInfo::garments
  std::vector<int32_t> rows;      // rows of the concatenated garments (N, 3)
  std::vector<int32_t> carriers;  // body vertices
};

// A group per garment with pinned vertices (GarmentMesh::pinned), its carriers chosen in one
// frame: garments (N, 3) and body (B, 3) of that frame, in the file's units. The carriers are the
// body vertices inside the loop the pins draw (within the loop's mean radius of its centre across
// the up axis, and within 5 cm of its heights): a waistband's loop holds the torso and leaves out
// arms and hands. When fewer than 3 lie inside (the pins draw no loop), those within 5 cm of a
// pin; failing that, the whole body.
std::vector<PinGroup> pin_groups(const SequenceInfo& info, const Eigen::Ref<const Points>& garments,
                                 const Eigen::Ref<const Points>& body);

// Writes each group's rows of x as the rows of x_before moved by the rigid motion of its carriers
// from body_before to body (each (B, 3); x and x_before (N, 3)). Returns how many rows it wrote.
int64_t carry_pins(const std::vector<PinGroup>& groups, const Eigen::Ref<const Points>& body_before,
                   const Eigen::Ref<const Points>& body, const Eigen::Ref<const Points>& x_before, Points& x);

// Rigs a scene's pins from its body: every frame's pinned rows from `reference` on become their rows
// at `reference` moved by the rigid motion of their carriers from that frame's body to this
// frame's, and the sequence says it records its pins. The carriers are chosen at the first frame
// loaded (a rest pose in generated data and in `simulate`'s scenes), where no hand reaches into the
// loop. One fit from a fixed frame, not a chain of frame-to-frame fits, so the fits' misses do not
// add up over a rollout.
// What `simulate` gives a user's scene, and what eval measures it by on data (--rig-pins).
void rig_pins(Sequence& seq, int reference);

}  // namespace layersnet::dataset
