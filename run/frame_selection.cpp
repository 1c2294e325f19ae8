#include "run/frame_selection.h"

namespace layersnet {

dataset::FrameSelection frame_selection_for(const DataConfig& d) {
  dataset::FrameSelection s;
  s.start_frame = d.first_frame - 2;  // sample_frames starts at start_frame + 2
  s.first_offset = 2;
  s.max_frames = d.max_frames > 0 ? d.max_frames + 2 : -1;
  return s;
}

}  // namespace layersnet
