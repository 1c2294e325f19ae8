// libFuzzer target over the readers of the files a user hands `layersnet simulate`
// (scripts/fuzz.sh builds and runs it). Input byte 0 selects the reader (value % 4), the rest is
// the file's bytes:
//   0  OBJ (dataset::read_obj: garments, body frames, a PC2's topology);
//   1  PC2 point cache (dataset::read_pc2: a body motion);
//   2  wind CSV (eval::read_wind);
//   3  BVH motion capture (eval::read_bvh_header, the check before Blender runs).
// Every rejection must be a DatasetError or SimulateError; whatever a reader accepts must hold
// what its header promises (finite positions, indices in range, the counts it reports).
// Anything else (crash, sanitizer report, other exception, a broken promise) is a finding.
#include "dataset/error.h"
#include "dataset/mesh_io.h"
#include "simulate/motion.h"
#include "simulate/simulate.h"
#include "simulate/wind.h"

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <string>
#include <unistd.h>

using namespace layersnet;

namespace {

void promise(bool kept, const char* what) {
  if (kept) return;
  std::fprintf(stderr, "fuzz_user_files: a reader accepted a file that breaks its promise: %s\n", what);
  std::abort();
}

void check_obj(const std::string& path) {
  const dataset::ObjMesh m = dataset::read_obj(path);
  promise(m.positions.allFinite(), "OBJ positions finite");
  promise(m.faces.rows() > 0, "OBJ has faces");
  promise(m.faces.minCoeff() >= 0 && m.faces.maxCoeff() < m.positions.rows(), "OBJ face indices in range");
  if (m.has_uv()) {
    promise(m.uv.allFinite(), "OBJ texture coordinates finite");
    const std::vector<int32_t> islands = dataset::uv_islands(m.faces, m.uv);
    promise(islands.size() == static_cast<size_t>(m.faces.rows()), "one UV island id per face");
  }
}

void check_pc2(const std::string& path) {
  const dataset::PointCache c = dataset::read_pc2(path);
  promise(!c.frames.empty(), "PC2 has a sample");
  for (const auto& f : c.frames) {
    promise(f.rows() == c.frames.front().rows() && f.rows() > 0, "PC2 samples of one point count");
    promise(f.allFinite(), "PC2 points finite");
  }
}

void check_wind(const std::string& path) {
  for (const eval::WindRow& r : eval::read_wind(path)) {
    promise(r.frame >= 0 && std::isfinite(r.strength) && r.strength >= 0, "wind row frame and strength valid");
    promise(std::isfinite(r.direction.norm()) && (r.strength == 0 || r.direction.norm() > 0), "wind direction usable");
  }
}

void check_bvh(const std::string& path) {
  const eval::BvhHeader h = eval::read_bvh_header(path);
  promise(h.frames >= 1 && h.frame_time > 0 && std::isfinite(h.rate()) && h.channels > 0, "BVH motion header valid");
  bool hips = false;
  for (const std::string& j : h.joints) hips |= j == "Hips";
  promise(hips, "BVH has a Hips joint");
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size < 1) return 0;
  static const std::string base = "/tmp/layersnet_fuzz_user_" + std::to_string(getpid());
  static const char* const kExt[] = {".obj", ".pc2", ".csv", ".bvh"};
  const int mode = data[0] % 4;
  const std::string path = base + kExt[mode];
  {
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    out.write(reinterpret_cast<const char*>(data + 1), static_cast<std::streamsize>(size - 1));
  }
  try {
    switch (mode) {
      case 0: check_obj(path); break;
      case 1: check_pc2(path); break;
      case 2: check_wind(path); break;
      default: check_bvh(path); break;
    }
  } catch (const dataset::DatasetError&) {
  } catch (const eval::SimulateError&) {
  }
  std::remove(path.c_str());
  return 0;
}
