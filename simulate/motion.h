#pragma once
// Motion capture as the body of a user's scene: a BVH clip retargeted by Blender onto the
// generator's body rig (generate/retarget_bvh.py, the rig and retargeting of generate/body_rig.py),
// written as a PC2 point cache with its topology OBJ, which simulate then reads as any PC2 body.
#include <string>
#include <vector>

namespace layersnet::eval {

// What a BVH file's text says about its skeleton and motion.
struct BvhHeader {
  std::vector<std::string> joints;  // ROOT and JOINT names in file order
  int channels = 0;                 // numbers per motion line (sum of CHANNELS)
  int frames = 0;                   // "Frames:"
  double frame_time = 0;            // "Frame Time:" in seconds
  double rate() const { return 1.0 / frame_time; }
};

// Reads and checks a BVH file: HIERARCHY, one ROOT, balanced braces, CHANNELS counts, a joint
// named Hips (the rig is driven from it), MOTION with Frames > 0 and a Frame Time > 0, and
// every one of those frames a line of `channels` finite numbers. Throws SimulateError
// "<file>: line N: <what is wrong and the fix>". The skeleton's joint set is matched against
// the known skeletons by the Blender script (generate/body_rig.py), which owns them.
BvhHeader read_bvh_header(const std::string& path);

struct MotionInput {
  std::string bvh;
  int bvh_start = 1;   // first BVH frame played (CMU clips: frame 0 is a calibration pose)
  int frames = 0;      // body frames to write, the rest pose and the ramp included (0 = to the clip's end)
  float fps = 30.f;    // frames per second of the written motion
  float yaw_deg = 0;   // the clip turned about the up axis
  float scale = 10.f;  // units per metre of the written files (simulate's --scale)
  char up_axis = 'z';  // up axis of the written files (simulate's --up)
  std::string blender = "blender";
  std::string script;  // generate/retarget_bvh.py
};

// Checks the BVH (read_bvh_header, bvh_start within its frames), then runs Blender headless to
// write `out_dir`/body.pc2 and `out_dir`/body.obj: frame 0 the rest pose of the generator's body,
// a ramp into the clip, then the clip resampled to `fps`. Blender's output goes to
// `out_dir`/blender.log, which stays when Blender fails for a reason the script could not name
// (the folder is removed when it names one). Throws SimulateError naming the BVH file and the fix.
void retarget_bvh(const MotionInput& input, const std::string& out_dir);

}  // namespace layersnet::eval
