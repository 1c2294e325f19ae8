// BVH header check and the Blender retargeting run (see motion.h).
#include "simulate/motion.h"

#include "simulate/simulate.h"

#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>

namespace layersnet::eval {
namespace fs = std::filesystem;

namespace {

std::string quote(const std::string& s) {
  std::string q = "'";
  for (char c : s) q += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return q + "'";
}

// A whole number or a decimal: strtod on the full token, nothing left over.
bool parse_double(const std::string& token, double& value) {
  if (token.empty()) return false;
  char* end = nullptr;
  errno = 0;
  value = std::strtod(token.c_str(), &end);
  return end == token.c_str() + token.size() && errno == 0;
}

}  // namespace

BvhHeader read_bvh_header(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw SimulateError(path + ": cannot be opened; give a BVH motion-capture file (e.g. a CMU clip)");
  BvhHeader h;
  std::string line, word;
  int line_no = 0, depth = 0, roots = 0;
  bool hierarchy = false, motion = false, hips = false;
  auto where = [&] { return path + ": line " + std::to_string(line_no); };
  auto fail = [&](const std::string& what) -> void { throw SimulateError(where() + ": " + what); };
  while (!motion && std::getline(in, line)) {
    ++line_no;
    std::istringstream words(line);
    if (!(words >> word)) continue;
    if (!hierarchy) {
      if (word != "HIERARCHY") fail("a BVH file starts with HIERARCHY; this is not a BVH file");
      hierarchy = true;
    } else if (word == "ROOT" || word == "JOINT") {
      std::string name;
      if (!(words >> name)) fail(word + " without a name");
      if (word == "ROOT" && (++roots > 1 || depth != 0)) fail("a second ROOT; the file must hold one skeleton");
      if (word == "JOINT" && depth == 0) fail("JOINT " + name + " outside the ROOT's braces");
      h.joints.push_back(name);
      hips |= name == "Hips";
    } else if (word == "{") {
      ++depth;
    } else if (word == "}") {
      if (--depth < 0) fail("a '}' without its '{'");
    } else if (word == "CHANNELS") {
      int n = -1;
      if (!(words >> n) || n < 0 || n > 6) fail("CHANNELS needs a count from 0 to 6");
      h.channels += n;
    } else if (word == "MOTION") {
      if (depth != 0) fail("MOTION inside an unclosed '{' of the HIERARCHY");
      motion = true;
    } else if (word != "OFFSET" && word != "End") {
      fail("'" + word + "' is not part of a BVH HIERARCHY");
    }
  }
  if (!hierarchy) throw SimulateError(path + ": is empty; give a BVH motion-capture file");
  if (!motion) throw SimulateError(path + ": the file ends before MOTION; the clip has no motion section");
  if (roots == 0) throw SimulateError(path + ": no ROOT joint in the HIERARCHY");
  if (!hips)
    throw SimulateError(path + ": no joint named Hips (joints: " + std::to_string(h.joints.size()) +
                        ", the first " + h.joints.front() +
                        "); the body rig is driven from the hips: use a CMU-style skeleton whose root is Hips");
  if (h.channels == 0) throw SimulateError(path + ": the HIERARCHY declares no CHANNELS; the clip cannot move");
  auto header_value = [&](const std::string& key) {
    while (std::getline(in, line)) {
      ++line_no;
      if (line.find_first_not_of(" \t\r") == std::string::npos) continue;
      const auto colon = line.find(':');
      std::string k = line.substr(0, colon == std::string::npos ? 0 : colon);
      std::istringstream rest(colon == std::string::npos ? "" : line.substr(colon + 1));
      std::string value;
      if (k != key || !(rest >> value)) fail("expected '" + key + ": <number>' after MOTION");
      double v = 0;
      if (!parse_double(value, v) || !std::isfinite(v)) fail("'" + value + "' is not a number");
      return v;
    }
    throw SimulateError(path + ": the file ends before '" + key + ":'");
  };
  const double frames = header_value("Frames");
  {
    char shown[32];
    std::snprintf(shown, sizeof shown, "%g", frames);
    if (frames < 1 || frames != std::floor(frames) || frames > 1e7)
      fail(std::string("Frames: ") + shown + "; the clip has no frames to play (a BVH needs a whole number of Frames >= 1)");
  }
  h.frames = static_cast<int>(frames);
  h.frame_time = header_value("Frame Time");
  if (!(h.frame_time > 0) || h.frame_time > 10) fail("Frame Time must be seconds per frame, > 0 (e.g. 0.0083333 for 120 Hz)");
  for (int f = 0; f < h.frames; ++f) {
    if (!std::getline(in, line)) {
      ++line_no;
      fail("the clip ends after " + std::to_string(f) + " of its " + std::to_string(h.frames) +
           " frames (Frames: says more than the file holds; the file may be truncated)");
    }
    ++line_no;
    std::istringstream numbers(line);
    int count = 0;
    double v = 0;
    for (std::string token; numbers >> token; ++count) {
      if (!parse_double(token, v) || !std::isfinite(v))
        fail("'" + token + "' is not a finite number (frame " + std::to_string(f) + ")");
    }
    if (count != h.channels)
      fail("frame " + std::to_string(f) + " has " + std::to_string(count) + " numbers, the HIERARCHY's CHANNELS say " +
           std::to_string(h.channels));
  }
  return h;
}

void retarget_bvh(const MotionInput& m, const std::string& out_dir) {
  const BvhHeader h = read_bvh_header(m.bvh);
  if (m.bvh_start < 0 || m.bvh_start >= h.frames)
    throw SimulateError(m.bvh + ": --bvh-start " + std::to_string(m.bvh_start) + " is outside its " +
                        std::to_string(h.frames) + " frames (0.." + std::to_string(h.frames - 1) + ")");
  if (m.frames == 1 || m.frames < 0)
    throw SimulateError("--frames " + std::to_string(m.frames) + ": a motion needs at least 2 frames (0 = the whole clip)");
  if (m.script.empty() || !fs::exists(m.script))
    throw SimulateError("generate/retarget_bvh.py not found beside the program (" + m.script +
                        "); reinstall, or run from the source tree");
  if (std::system((quote(m.blender) + " --version > /dev/null 2>&1").c_str()) != 0)
    throw SimulateError(m.bvh + ": a BVH clip is retargeted with Blender, and '" + m.blender +
                        "' does not run: install Blender (scripts/setup.sh) or pass --blender PATH");
  fs::create_directories(out_dir);
  const fs::path log = fs::path(out_dir) / "blender.log";
  char fps[32], scale[32], yaw[32];
  std::snprintf(fps, sizeof fps, "%.9g", m.fps);
  std::snprintf(scale, sizeof scale, "%.9g", m.scale);
  std::snprintf(yaw, sizeof yaw, "%.9g", m.yaw_deg);
  const std::string cmd = quote(m.blender) + " -b --factory-startup --python-exit-code 1 --python " + quote(m.script) +
                          " -- " + quote(fs::absolute(m.bvh).string()) + " " + quote(out_dir) + " --bvh-start " +
                          std::to_string(m.bvh_start) + " --frames " + std::to_string(m.frames) + " --fps " + fps +
                          " --scale " + scale + " --up " + std::string(1, m.up_axis) + " --yaw " + yaw + " > " +
                          quote(log.string()) + " 2>&1";
  const int rc = std::system(cmd.c_str());
  const bool written = fs::exists(fs::path(out_dir) / "body.pc2") && fs::exists(fs::path(out_dir) / "body.obj");
  if (rc == 0 && written) return;
  std::ifstream in(log);
  std::string line, reason;
  while (std::getline(in, line))
    if (line.rfind("retarget_bvh: error: ", 0) == 0) reason = line.substr(21);
  if (!reason.empty()) {  // the script named the file and the fix: its log adds nothing
    in.close();
    std::error_code ec;
    fs::remove_all(out_dir, ec);
    throw SimulateError(reason);
  }
  throw SimulateError(m.bvh + ": Blender could not retarget the clip (exit " + std::to_string(rc) + "); its log: " +
                      log.string());
}

}  // namespace layersnet::eval
