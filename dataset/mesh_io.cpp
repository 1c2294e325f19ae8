// OBJ and PC2 reading and writing (see mesh_io.h).
#include "dataset/mesh_io.h"

#include <array>
#include <bit>
#include <cerrno>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <map>
#include <numeric>
#include <unordered_map>

namespace layersnet::dataset {
namespace {

std::string line_ref(long line) { return "line " + std::to_string(line); }

// Parses the floats of a "v"/"vt" line after its keyword; returns how many were read.
int parse_floats(const char* s, float* out, int max_count) {
  int n = 0;
  while (n < max_count) {
    char* end = nullptr;
    errno = 0;
    const float value = std::strtof(s, &end);
    if (end == s) break;
    out[n++] = value;
    s = end;
  }
  return n;
}

// 1-based or negative (relative) OBJ index -> 0-based, or -1 when out of range.
int resolve_index(long index, size_t count) {
  if (index > 0 && static_cast<size_t>(index) <= count) return static_cast<int>(index - 1);
  // -(index + 1) cannot overflow, where -index does for the smallest long (strtol saturates there).
  if (index < 0 && static_cast<unsigned long>(-(index + 1)) < count) return static_cast<int>(static_cast<long>(count) + index);
  return -1;
}

}  // namespace

ObjMesh read_obj(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw DatasetError(path, "file", "cannot be opened (check the path)");
  std::vector<float> v, vt;  // flat x y z / u v
  std::vector<int32_t> faces;
  std::vector<float> corner_uv;
  bool every_corner_has_uv = true;
  int quads = 0;
  std::string text;
  long line = 0;
  while (std::getline(in, text)) {
    ++line;
    const char* s = text.c_str();
    while (*s == ' ' || *s == '\t') ++s;
    if (s[0] == 'v' && (s[1] == ' ' || s[1] == '\t')) {
      float p[3];
      if (parse_floats(s + 2, p, 3) != 3) throw DatasetError(path, line_ref(line), "a 'v' line needs x y z");
      if (!std::isfinite(p[0]) || !std::isfinite(p[1]) || !std::isfinite(p[2]))
        throw DatasetError(path, line_ref(line), "vertex " + std::to_string(v.size() / 3 + 1) +
                                                     " is not finite (nan or inf); fix or re-export the mesh");
      v.insert(v.end(), p, p + 3);
    } else if (s[0] == 'v' && s[1] == 't' && (s[2] == ' ' || s[2] == '\t')) {
      float p[2];
      if (parse_floats(s + 3, p, 2) != 2) throw DatasetError(path, line_ref(line), "a 'vt' line needs u v");
      if (!std::isfinite(p[0]) || !std::isfinite(p[1]))
        throw DatasetError(path, line_ref(line), "texture coordinate " + std::to_string(vt.size() / 2 + 1) +
                                                     " is not finite (nan or inf); unwrap the mesh again");
      vt.insert(vt.end(), p, p + 2);
    } else if (s[0] == 'f' && (s[1] == ' ' || s[1] == '\t')) {
      std::array<int, 4> pos{}, tex{};
      int corners = 0;
      const char* c = s + 2;
      while (true) {
        while (*c == ' ' || *c == '\t' || *c == '\r') ++c;
        if (*c == '\0' || *c == '#') break;
        char* end = nullptr;
        const long vi = std::strtol(c, &end, 10);
        if (end == c) throw DatasetError(path, line_ref(line), "unreadable face corner '" + std::string(c) + "'");
        long ti = 0;
        c = end;
        if (*c == '/') {
          ++c;
          if (*c != '/') {
            ti = std::strtol(c, &end, 10);
            c = end;
          }
          if (*c == '/') {  // normal index: ignored
            ++c;
            std::strtol(c, &end, 10);
            c = end;
          }
        }
        if (corners < 4) {
          pos[corners] = resolve_index(vi, v.size() / 3);
          if (pos[corners] < 0)
            throw DatasetError(path, line_ref(line), "vertex index " + std::to_string(vi) + " is out of range (" +
                                                         std::to_string(v.size() / 3) + " vertices so far)");
          tex[corners] = ti == 0 ? -1 : resolve_index(ti, vt.size() / 2);
          if (ti != 0 && tex[corners] < 0)
            throw DatasetError(path, line_ref(line), "texture index " + std::to_string(ti) + " is out of range");
        }
        ++corners;
      }
      if (corners != 3 && corners != 4)
        throw DatasetError(path, line_ref(line),
                           "a face with " + std::to_string(corners) +
                               " corners; only triangles and quads are read: triangulate the mesh "
                               "(Blender: Triangulate modifier, or the OBJ exporter's 'Triangulated Mesh')");
      if (corners == 4) ++quads;
      static constexpr int kTri[2][3] = {{0, 1, 2}, {0, 2, 3}};
      for (int t = 0; t < corners - 2; ++t)
        for (int k : kTri[t]) {
          faces.push_back(pos[k]);
          if (tex[k] < 0) {
            every_corner_has_uv = false;
            corner_uv.insert(corner_uv.end(), {0.f, 0.f});
          } else {
            corner_uv.insert(corner_uv.end(), {vt[2 * tex[k]], vt[2 * tex[k] + 1]});
          }
        }
    }
  }
  if (faces.empty()) throw DatasetError(path, "file", "has no faces ('f' lines): not a mesh OBJ");
  ObjMesh m;
  m.positions = Eigen::Map<const Points>(v.data(), static_cast<Eigen::Index>(v.size() / 3), 3);
  m.faces = Eigen::Map<const Faces>(faces.data(), static_cast<Eigen::Index>(faces.size() / 3), 3);
  if (every_corner_has_uv) m.uv = Eigen::Map<const Uvs>(corner_uv.data(), static_cast<Eigen::Index>(corner_uv.size() / 2), 2);
  m.quads = quads;
  return m;
}

void write_obj(const std::string& path, const Eigen::Ref<const Points>& x, const Faces& faces, const Uvs* corner_uv,
               const Points* normals) {
  std::FILE* f = std::fopen(path.c_str(), "w");
  if (!f) throw DatasetError(path, "file", std::string("cannot be written: ") + std::strerror(errno));
  for (Eigen::Index i = 0; i < x.rows(); ++i) std::fprintf(f, "v %.9g %.9g %.9g\n", x(i, 0), x(i, 1), x(i, 2));
  std::vector<int> corner_vt;  // (F*3,) 1-based vt line of each corner
  if (corner_uv) {
    std::map<std::pair<uint32_t, uint32_t>, int> seen;  // exact UV value -> vt line
    corner_vt.resize(static_cast<size_t>(corner_uv->rows()));
    for (Eigen::Index c = 0; c < corner_uv->rows(); ++c) {
      const float u = (*corner_uv)(c, 0), w = (*corner_uv)(c, 1);
      const auto key = std::make_pair(std::bit_cast<uint32_t>(u), std::bit_cast<uint32_t>(w));
      auto [it, added] = seen.emplace(key, static_cast<int>(seen.size()) + 1);
      if (added) std::fprintf(f, "vt %.9g %.9g\n", u, w);
      corner_vt[c] = it->second;
    }
  }
  if (normals)
    for (Eigen::Index i = 0; i < normals->rows(); ++i)
      std::fprintf(f, "vn %.6f %.6f %.6f\n", (*normals)(i, 0), (*normals)(i, 1), (*normals)(i, 2));
  for (Eigen::Index i = 0; i < faces.rows(); ++i) {
    std::fputc('f', f);
    for (int c = 0; c < 3; ++c) {
      const int v = faces(i, c) + 1;
      if (corner_uv && normals)
        std::fprintf(f, " %d/%d/%d", v, corner_vt[3 * i + c], v);
      else if (corner_uv)
        std::fprintf(f, " %d/%d", v, corner_vt[3 * i + c]);
      else if (normals)
        std::fprintf(f, " %d//%d", v, v);
      else
        std::fprintf(f, " %d", v);
    }
    std::fputc('\n', f);
  }
  const bool failed = std::ferror(f) != 0;
  if (std::fclose(f) != 0 || failed)
    throw DatasetError(path, "file", std::string("write failed: ") + std::strerror(errno));
}

std::vector<int32_t> uv_islands(const Faces& faces, const Uvs& uv) {
  const Eigen::Index F = faces.rows();
  std::vector<int32_t> parent(static_cast<size_t>(F));
  std::iota(parent.begin(), parent.end(), 0);
  const auto find = [&](int32_t a) {
    while (parent[a] != a) a = parent[a] = parent[parent[a]];
    return a;
  };
  struct KeyHash {
    size_t operator()(const std::array<uint32_t, 3>& k) const {
      return (static_cast<size_t>(k[0]) * 0x9E3779B97F4A7C15ull) ^ (static_cast<size_t>(k[1]) << 21) ^ k[2];
    }
  };
  std::unordered_map<std::array<uint32_t, 3>, int32_t, KeyHash> first_face;  // (vertex, u, v) -> face
  for (Eigen::Index f = 0; f < F; ++f)
    for (int c = 0; c < 3; ++c) {
      const std::array<uint32_t, 3> key{static_cast<uint32_t>(faces(f, c)), std::bit_cast<uint32_t>(uv(3 * f + c, 0)),
                                        std::bit_cast<uint32_t>(uv(3 * f + c, 1))};
      const auto [it, added] = first_face.emplace(key, static_cast<int32_t>(f));
      if (!added) {
        const int32_t a = find(it->second), b = find(static_cast<int32_t>(f));
        if (a != b) parent[std::max(a, b)] = std::min(a, b);  // root = the island's first face
      }
    }
  std::vector<int32_t> island(static_cast<size_t>(F)), id_of_root(static_cast<size_t>(F), -1);
  int32_t next = 0;
  for (Eigen::Index f = 0; f < F; ++f) {
    const int32_t root = find(static_cast<int32_t>(f));
    if (id_of_root[root] < 0) id_of_root[root] = next++;
    island[f] = id_of_root[root];
  }
  return island;
}

namespace {
constexpr char kPc2Signature[12] = {'P', 'O', 'I', 'N', 'T', 'C', 'A', 'C', 'H', 'E', '2', '\0'};
struct Pc2Header {
  char signature[12];
  int32_t version;
  int32_t points;
  float start_frame;
  float sample_rate;
  int32_t samples;
};
static_assert(sizeof(Pc2Header) == 32);
static_assert(std::endian::native == std::endian::little, "PC2 files are little-endian");
}  // namespace

PointCache read_pc2(const std::string& path) {
  std::ifstream in(path, std::ios::binary | std::ios::ate);
  if (!in) throw DatasetError(path, "file", "cannot be opened (check the path)");
  const std::streamoff size = in.tellg();
  in.seekg(0);
  Pc2Header h{};
  if (size < static_cast<std::streamoff>(sizeof h) || !in.read(reinterpret_cast<char*>(&h), sizeof h) ||
      std::memcmp(h.signature, kPc2Signature, sizeof kPc2Signature) != 0)
    throw DatasetError(path, "header", "not a PC2 point cache (no POINTCACHE2 signature)");
  if (h.version != 1) throw DatasetError(path, "header", "PC2 version " + std::to_string(h.version) + ", expected 1");
  if (h.points <= 0 || h.samples <= 0)
    throw DatasetError(path, "header", "holds " + std::to_string(h.points) + " points x " + std::to_string(h.samples) +
                                           " samples; a point cache needs at least one of each");
  // Both counts are below 2^31, so their product times 12 bytes fits in 64 bits only when
  // bounded first: a header that claims more than the file could hold is refused below anyway.
  const std::streamoff per_sample = static_cast<std::streamoff>(h.points) * 12;
  const std::streamoff expected = h.samples > (size - static_cast<std::streamoff>(sizeof h)) / per_sample
                                      ? -1
                                      : static_cast<std::streamoff>(sizeof h) + per_sample * h.samples;
  if (size != expected)
    throw DatasetError(path, "file", std::to_string(size) + " bytes, but its header (" + std::to_string(h.points) +
                                         " points x " + std::to_string(h.samples) + " samples) needs " +
                                         (expected < 0 ? std::string("more") : std::to_string(expected)) +
                                         ": the file is truncated or damaged");
  PointCache cache;
  cache.start_frame = h.start_frame;
  cache.sample_rate = h.sample_rate;
  cache.frames.resize(static_cast<size_t>(h.samples));
  for (Points& frame : cache.frames) {
    frame.resize(h.points, 3);
    in.read(reinterpret_cast<char*>(frame.data()), static_cast<std::streamsize>(frame.size() * sizeof(float)));
    if (!in) throw DatasetError(path, "file", "read failed");
    if (!frame.allFinite()) {
      Eigen::Index row = 0;
      while (frame.row(row).allFinite()) ++row;
      throw DatasetError(path, "sample " + std::to_string(&frame - cache.frames.data()),
                         "point " + std::to_string(row) + " is not finite (nan or inf); bake the cache again");
    }
  }
  return cache;
}

void write_pc2(const std::string& path, const PointCache& cache) {
  if (cache.frames.empty()) throw DatasetError(path, "file", "a point cache needs at least one frame");
  const Eigen::Index points = cache.frames.front().rows();
  Pc2Header h{};
  std::memcpy(h.signature, kPc2Signature, sizeof kPc2Signature);
  h.version = 1;
  h.points = static_cast<int32_t>(points);
  h.start_frame = cache.start_frame;
  h.sample_rate = cache.sample_rate;
  h.samples = static_cast<int32_t>(cache.frames.size());
  std::ofstream out(path, std::ios::binary);
  out.write(reinterpret_cast<const char*>(&h), sizeof h);
  for (const Points& frame : cache.frames) {
    if (frame.rows() != points) throw DatasetError(path, "file", "frames of a point cache differ in point count");
    out.write(reinterpret_cast<const char*>(frame.data()), static_cast<std::streamsize>(frame.size() * sizeof(float)));
  }
  out.close();
  if (!out) throw DatasetError(path, "file", std::string("cannot be written: ") + std::strerror(errno));
}

}  // namespace layersnet::dataset
