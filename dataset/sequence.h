#pragma once
// One D-LAYERS-H5 sequence (docs/dlayers-h5.md) in memory, and its reader/writer.
//
// Dimension letters used throughout the data layer:
//   T frames, N garment vertices, F garment faces, B body vertices, Fb body faces,
//   P patches, K body neighbours per patch.
// Positions are in scene units (spec attr `scale` = units per metre), world frame.
// In memory everything is float32 (float64 files are converted on read; a value beyond
// float32 range is reported as non-finite), indices are int32.
//
// Reading is split in two so that a data set larger than RAM can be streamed:
//   SequenceFile  opens a file, checks every rule of the spec that does not need the
//                 per-frame positions, and holds the small static part (SequenceInfo);
//   read_frames() reads a window of frames of the body and garment positions (hyperslab)
//                 and checks those values (finite).
// read_sequence() does both for all frames.
#include "dataset/error.h"
#include "dataset/h5.h"

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <algorithm>
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

namespace layersnet::dataset {

using Points = Eigen::Matrix<float, Eigen::Dynamic, 3, Eigen::RowMajor>;  // (rows, 3)
using Faces = Eigen::Matrix<int32_t, Eigen::Dynamic, 3, Eigen::RowMajor>;  // (F, 3)
using Uvs = Eigen::Matrix<float, Eigen::Dynamic, 2, Eigen::RowMajor>;     // (F*3, 2)
using Quats = Eigen::Matrix<float, Eigen::Dynamic, 4, Eigen::RowMajor>;   // (T, 4) w,x,y,z

// Physical attributes of one garment (spec: /garments/<name> attrs).
struct GarmentAttributes {
  float tension_stiffness = 50.f;  // D-LAYERS range 15..100
  float bending_stiffness = 50.f;  // 15..200
  float mass = 0.5f;               // 0.2..0.8
  float self_friction = 60.f;      // 40..80
};

inline constexpr float kPinnedWeight = 0.5f;

// The static (frame-independent) part of one garment.
struct GarmentMesh {
  std::string name;          // HDF5 group name
  std::string type;          // e.g. "tee", "jacket"
  int num_vertices = 0;      // N
  Faces faces;               // (F, 3)
  Uvs uv;                    // (F*3, 2): corner c of face f is row 3f+c
  std::vector<int32_t> panel;  // (F,) UV island of each face, >= 0
  Points rest;               // (N, 3) T-pose template, or 0 rows when the file has none
  // (N,) weight 0..1 of the simulator's pin group, or empty when the file has none. A vertex of
  // weight >= kPinnedWeight is attached to the body (a waistband, a top edge).
  std::vector<float> pin;
  bool pinned(int v) const { return !pin.empty() && pin[static_cast<size_t>(v)] >= kPinnedWeight; }
  int num_pinned() const {
    return static_cast<int>(std::count_if(pin.begin(), pin.end(), [](float w) { return w >= kPinnedWeight; }));
  }
  GarmentAttributes attributes;
  int num_faces() const { return static_cast<int>(faces.rows()); }
};

// Everything of a sequence except the per-frame body and garment positions.
struct SequenceInfo {
  std::string path;                 // file name used in error messages
  float fps = 30.f;                 // frames per second
  char up_axis = 'z';               // 'z' or 'y'
  Eigen::Vector3f gravity{0.f, 0.f, -9.8f};  // scene units / s^2 (D-LAYERS value)
  float scale = 10.f;               // scene units per metre
  int num_frames = 0;               // T >= 3
  int num_body_vertices = 0;        // B
  Faces body_faces;                 // (Fb, 3), counter-clockwise seen from outside
  float body_friction = 60.f;       // D-LAYERS range 40..80
  bool has_translation = false;     // /body/translation present in the file
  Points translation;               // (T, 3) body root translation (zeros if absent)
  std::vector<GarmentMesh> garments;  // layer order: innermost first, outer layer last
  bool has_wind = false;            // /wind present
  Quats wind_rotation;              // (T, 4) unit quaternions (w, x, y, z); 0 rows without wind
  Eigen::VectorXf wind_strength;    // (T,) 0 = no wind; empty without wind
  // Optional root attrs of `layersnet generate`: frames of rest pose, then of blending into the
  // motion (0 when absent).
  int rest_frames = 0;
  int ramp_frames = 0;
  // Optional root attrs of `layersnet generate` that say how Blender was driven:
  // wind_field_factor: Blender's field strength = stored strength x this (1 when absent);
  // stiffness_groups "per_layer": every layer was simulated with its stored tension and bending;
  // absent or "outer_max": with base inner + |outer - inner| on the outer layer (so an outer value
  // below the inner one was simulated as 2 x inner - outer).
  float wind_field_factor = 1.f;
  bool stiffness_per_layer = false;
  // The garments' frames record where the simulator drove the pinned vertices (a file's do; a
  // scene built for `simulate` holds only the rest shape there, so its pins must be carried).
  bool pins_recorded = true;

  // First frame after the rest pose and the ramp: where the motion proper starts.
  int settled_frame() const { return rest_frames + ramp_frames; }
  int num_garments() const { return static_cast<int>(garments.size()); }
  int64_t total_garment_vertices() const;
  // Rows of the pinned vertices among the garments' vertices in layer order (ascending).
  std::vector<Eigen::Index> pinned_rows() const;
  // Bytes of per-frame positions (body + garments) of one frame in memory.
  int64_t bytes_per_frame() const;
};

// Positions of frames [first, first + count).
struct FrameWindow {
  int first = 0;
  int count = 0;
  Points body;                  // (count*B, 3): frame t at rows (t-first)*B ...
  std::vector<Points> garments; // per garment (count*N, 3)

  // Rows of frame t (absolute index) of the body / garment g.
  auto body_at(int t, int num_body_vertices) const {
    return body.middleRows(static_cast<Eigen::Index>(t - first) * num_body_vertices, num_body_vertices);
  }
  auto garment_at(int g, int t, int num_vertices) const {
    return garments[g].middleRows(static_cast<Eigen::Index>(t - first) * num_vertices, num_vertices);
  }
  bool contains(int t) const { return t >= first && t < first + count; }
  int64_t bytes() const;
};

// A whole sequence in memory (all frames).
struct Sequence {
  SequenceInfo info;
  FrameWindow frames;  // first = 0, count = T
  auto body_at(int t) const { return frames.body_at(t, info.num_body_vertices); }
  auto garment_at(int g, int t) const {
    return frames.garment_at(g, t, info.garments[g].num_vertices);
  }
};

// An open, header-checked sequence file. Not thread-safe (HDF5 is not); one per thread.
class SequenceFile {
 public:
  // Opens and checks; throws DatasetError naming file, object path and problem.
  explicit SequenceFile(const std::string& path);
  // Same over an in-memory file image (`name` is used in messages only).
  SequenceFile(std::span<const uint8_t> image, const std::string& name);
  ~SequenceFile();
  SequenceFile(SequenceFile&&) noexcept;
  SequenceFile& operator=(SequenceFile&&) noexcept;

  const SequenceInfo& info() const { return info_; }
  // Reads and checks positions of frames [first, first+count); requires 0 <= first,
  // first + count <= T.
  FrameWindow read_frames(int first, int count) const;
  Sequence read_all() const;

 private:
  void load();
  h5::Handle file_;
  SequenceInfo info_;
};

Sequence read_sequence(const std::string& path);

// The mirror image of a sequence in the plane x = 0: positions, rest shapes, the root translation
// and gravity get x → −x, the wind blows along its mirrored direction, and every face is wound
// the other way round so that normals still point out of the body and the cloth. Every term of
// Blender's cloth (and of losses/physics.h) is symmetric under it, so the image is a sequence the
// simulator could have made: data.mirror trains on it beside the original. x is never the up axis
// (z or y). Mirroring twice gives the original back exactly.
SequenceInfo mirrored(SequenceInfo info);
// x → −x on every row of positions (rows, 3).
void mirror_points(Points& points);
// x → −x on every body and garment position of the window.
void mirror_positions(FrameWindow& frames);
// The whole sequence's image: mirrored(info) and mirror_positions(frames).
void mirror(Sequence& seq);

struct SequenceWriteOptions {
  bool float64 = false;  // float arrays as float64 (default float32)
  bool int64 = false;    // index arrays as int64 (default int32)
  int gzip = 0;          // 0: contiguous; 1..9: chunked, shuffle + gzip at that level
  bool write_translation = true;  // write /body/translation
};
// Writes a sequence that passes check_dlayers_h5.py. Throws DatasetError when the in-memory
// sequence itself breaks the spec (checked by validate_sequence first).
void write_sequence(const std::string& path, const Sequence& seq,
                    const SequenceWriteOptions& options = {});

// Writes the sequence's groups, datasets and attributes into an already created HDF5 file
// (e.g. an in-memory core-driver file); `name` is used in messages. write_sequence =
// validate_sequence + create file + this.
void write_sequence_contents(hid_t file, const Sequence& seq, const SequenceWriteOptions& options,
                             const std::string& name);

// Checks the in-memory sequence against the spec (shapes, finiteness, index ranges, unit
// quaternions, ...). Used by the writer; `file` names it in messages.
void validate_sequence(const Sequence& seq, const std::string& file);

// Attribute names shared by reader and writer.
inline constexpr const char* kFormatName = "dlayers-h5";
inline constexpr int kFormatVersion = 1;
inline constexpr double kQuaternionTolerance = 1e-3;  // | |q| - 1 | allowed
// Bound on every coordinate (positions, root translation, rest shapes), scene units: 1 km at
// the x10 convention, where a scene spans metres. Beyond it the data is damaged, and its
// squares would overflow the float32 statistics.
inline constexpr double kMaxSceneCoordinate = 1e4;

}  // namespace layersnet::dataset
