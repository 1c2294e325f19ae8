#pragma once
// Mesh files of other tools: Wavefront OBJ (read and write) and PC2 point caches (Blender's
// Mesh Cache modifier, 3ds Max). Coordinates are passed through unchanged (the files' own units
// and axes); conversions belong to the caller.
//
// Errors are DatasetError "<file>: <line N | object>: <what is wrong and the fix>".
#include "dataset/sequence.h"

#include <string>
#include <vector>

namespace layersnet::dataset {

struct ObjMesh {
  Points positions;  // (V, 3) the "v" lines in file order
  Faces faces;       // (F, 3) 0-based; a quad a b c d becomes (a b c), (a c d)
  Uvs uv;            // (F*3, 2) corner c of face f at row 3f+c; 0 rows when a face lacks "vt"
  int quads = 0;     // quads split into two triangles
  bool has_uv() const { return uv.rows() == 3 * faces.rows() && faces.rows() > 0; }
};

// Reads v, vt and f lines (v/vt, v/vt/vn, v//vn, negative indices); vn, groups, materials and
// smoothing are ignored. Throws on a face that is not a triangle or a quad, an index out of
// range, or a file without faces.
ObjMesh read_obj(const std::string& path);

// Writes "v" lines (%.9g: float32 round-trips exactly), then per corner "vt" when `corner_uv`
// is given ((F*3, 2); equal UV values share one vt line), "vn" per vertex when `normals` is
// given ((V, 3)), and "f" lines. Throws naming the path when it cannot be written.
void write_obj(const std::string& path, const Eigen::Ref<const Points>& x, const Faces& faces,
               const Uvs* corner_uv = nullptr, const Points* normals = nullptr);

// UV islands: faces that share a corner with the same vertex and the same UV value belong to
// one island (a seam gives its vertices different UVs on each side). Ids 0, 1, ... in order of
// each island's first face: the panel ids of a D-LAYERS-H5 garment. faces (F, 3), uv (F*3, 2).
std::vector<int32_t> uv_islands(const Faces& faces, const Uvs& uv);

// PC2 point cache: a 32-byte header ("POINTCACHE2\0", version 1, points, start frame, sample
// rate, samples), then float32 x y z per point per sample, little-endian.
struct PointCache {
  float start_frame = 0.f;
  float sample_rate = 1.f;  // frames between samples
  std::vector<Points> frames;  // (samples,) each (points, 3)
};
PointCache read_pc2(const std::string& path);
// All frames must have the same number of rows (>= 1 frame).
void write_pc2(const std::string& path, const PointCache& cache);

}  // namespace layersnet::dataset
