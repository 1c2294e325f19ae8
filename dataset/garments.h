#pragma once
// The garments of a sequence as one layer-ordered point set: where each garment's rows lie,
// the inner layers' faces in that numbering, every mesh edge once with its rest length.
//
// Rows: garments concatenated in the file's layer order (innermost first), (N, 3); the last
// garment is the outer layer when there are two or more.
#include "dataset/sequence.h"

#include <Eigen/Core>

#include <cstdint>
#include <string>
#include <utility>
#include <vector>

namespace layersnet::dataset {

struct GarmentLayout {
  std::vector<int32_t> offsets;    // (G+1,) first row of each garment
  std::vector<Faces> faces;        // per garment, local indices
  std::vector<std::string> types;  // per garment
  int num_garments() const { return static_cast<int>(types.size()); }
  int num_vertices() const { return offsets.empty() ? 0 : offsets.back(); }
  bool layered() const { return num_garments() >= 2; }  // the last garment is the outer layer
  int outer_vertices() const { return layered() ? offsets.back() - offsets[offsets.size() - 2] : 0; }
};
GarmentLayout garment_layout(const SequenceInfo& info);
// Inner garments' faces re-indexed into the concatenation of garments [0, G-1): (F_i, 3).
Faces inner_faces(const GarmentLayout& layout);

// Garment positions of frame t (inside `frames`) concatenated in layer order: (N, 3).
Points garments_at(const SequenceInfo& info, const FrameWindow& frames, int t);

// Rest shapes (N, 3), scene units: each garment's /rest template, else its rows of
// `first_frame` (the garments of frame 0, (N, 3)).
Points rest_shapes(const SequenceInfo& info, const Points& first_frame);

// Every mesh edge once, as pairs of rows, garment by garment, with its rest length (scene
// units; 0 for coincident rest vertices).
struct GarmentEdges {
  std::vector<std::pair<Eigen::Index, Eigen::Index>> rows;
  std::vector<double> rest;
};
GarmentEdges garment_edges(const SequenceInfo& info, const Points& rest);
// Strain |length / rest length − 1| of every edge in x (N, 3), in edge order (edges of zero
// rest length skipped).
std::vector<double> edge_strains(const GarmentEdges& edges, const Points& x);

}  // namespace layersnet::dataset
