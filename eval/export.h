#pragma once
// Mesh export of a rollout: predicted and ground-truth meshes per frame as
// OBJ or PLY (body, each garment) for Blender / MeshLab, and a PNG strip of a few frames.
//
// Files in the output folder (frame numbers are the sequence's, 4 digits):
//   body_<frame>.<ext>                 the body (ground truth, it drives the rollout)
//   pred_<garment>_<frame>.<ext>       predicted garment
//   gt_<garment>_<frame>.<ext>         ground-truth garment
//   strip.png                          top row prediction, bottom row ground truth
// Coordinates: world, scene units, as stored in the sequence file (no rescaling).
#include "eval/rollout.h"

#include <string>
#include <vector>

namespace layersnet::eval {

// x (V, 3), faces (F, 3); ascii OBJ ("v", "f" 1-based) or binary little-endian PLY.
void write_obj(const std::string& path, const Eigen::Ref<const Points>& x, const dataset::Faces& faces);
void write_ply(const std::string& path, const Eigen::Ref<const Points>& x, const dataset::Faces& faces);

struct ExportOptions {
  std::string format = "obj";  // "obj" | "ply"
  int strip_frames = 4;        // panels of strip.png, evenly spread over the rollout (0 = none)
  int panel_size = 256;        // pixels per panel side
};

// Writes every frame of `r` (and the matching ground truth) into `dir` (created).
// Returns the number of mesh files written.
int export_rollout(const std::string& dir, const dataset::Sequence& seq, const Rollout& r, const ExportOptions& options);

// Renders strip.png: for each chosen frame a prediction panel over a ground-truth panel.
void render_strip(const std::string& path, const dataset::Sequence& seq, const Rollout& r, int frames, int panel_size);

}  // namespace layersnet::eval
