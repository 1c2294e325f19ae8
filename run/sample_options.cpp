#include "run/sample_options.h"

namespace layersnet {

dataset::SampleOptions sample_options_for(const ModelConfig& m) {
  dataset::SampleOptions o;
  o.patch_size = static_cast<float>(m.patch_size);
  o.neighbours.world_radius = static_cast<float>(m.world_radius);
  o.neighbours.body_radius = static_cast<float>(m.body_radius);
  o.neighbours.body_k = m.body_neighbors;
  o.neighbours.body_query =
      m.body_query == "first" ? dataset::BodyQuery::kFirstInIndexOrder : dataset::BodyQuery::kNearest;
  // The model keeps valid slots only (model/README.md quirk 3), so no duplicate padding.
  o.neighbours.official_padding = false;
  return o;
}

dataset::FrameSelection frame_selection_for(const DataConfig& d) {
  dataset::FrameSelection s;
  s.start_frame = d.first_frame - 2;  // sample_frames starts at start_frame + 2
  s.first_offset = 2;
  s.max_frames = d.max_frames > 0 ? d.max_frames + 2 : -1;
  return s;
}

}  // namespace layersnet
