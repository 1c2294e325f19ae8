// D-LAYERS-H5 writer. The in-memory sequence is checked first so that nothing the project
// writes can fail the format's validator check_dlayers_h5.py.
#include "dataset/sequence.h"

#include <cmath>
#include <filesystem>
#include <set>

namespace layersnet::dataset {
namespace {

void check_finite(const float* p, Eigen::Index n, const std::string& file, const std::string& path) {
  for (Eigen::Index i = 0; i < n; ++i)
    if (!std::isfinite(p[i]))
      throw DatasetError(file, path, "non-finite value at flat index " + std::to_string(i));
}

// Finite and within the scene extent (kMaxSceneCoordinate), as the reader requires.
void check_coordinates(const float* p, Eigen::Index n, const std::string& file, const std::string& path) {
  check_finite(p, n, file, path);
  for (Eigen::Index i = 0; i < n; ++i)
    if (std::abs(p[i]) > kMaxSceneCoordinate)
      throw DatasetError(file, path, "coordinate " + std::to_string(p[i]) + " at flat index " + std::to_string(i) +
                                         " is beyond the scene extent +-" +
                                         std::to_string(static_cast<int>(kMaxSceneCoordinate)) + " units");
}

void check_faces(const Faces& f, int n, const std::string& file, const std::string& path) {
  if (f.rows() == 0) throw DatasetError(file, path, "has no faces");
  if (f.minCoeff() < 0 || f.maxCoeff() >= n)
    throw DatasetError(file, path, "face indices out of range [0, " + std::to_string(n) + ")");
}

}  // namespace

void validate_sequence(const Sequence& seq, const std::string& file) {
  const SequenceInfo& s = seq.info;
  const int T = s.num_frames;
  auto fail = [&](const std::string& path, const std::string& msg) { throw DatasetError(file, path, msg); };
  if (T < 3) fail("/body/vertices", "T = " + std::to_string(T) + " frames, must be >= 3");
  if (!(s.fps > 0) || !(s.scale > 0) || !s.gravity.allFinite()) fail("/", "fps, scale must be > 0, gravity finite");
  if (s.up_axis != 'z' && s.up_axis != 'y') fail("/", "up_axis must be 'z' or 'y'");
  if (s.rest_frames < 0 || s.ramp_frames < 0) fail("/", "rest_frames and ramp_frames must be >= 0");
  if (seq.frames.first != 0 || seq.frames.count != T) fail("/", "the sequence must hold all frames");
  if (s.num_body_vertices <= 0 || seq.frames.body.rows() != static_cast<Eigen::Index>(T) * s.num_body_vertices)
    fail("/body/vertices", "shape does not match (T, B, 3)");
  check_coordinates(seq.frames.body.data(), seq.frames.body.size(), file, "/body/vertices");
  check_faces(s.body_faces, s.num_body_vertices, file, "/body/faces");
  if (s.translation.rows() != T) fail("/body/translation", "must have T rows");
  check_coordinates(s.translation.data(), s.translation.size(), file, "/body/translation");
  if (!std::isfinite(s.body_friction) || s.body_friction < 0) fail("/body", "friction must be finite and >= 0");
  if (s.garments.empty()) fail("/garments", "has no garment (at least one is required)");
  if (seq.frames.garments.size() != s.garments.size()) fail("/garments", "positions missing for some garments");
  std::set<std::string> names;
  for (size_t gi = 0; gi < s.garments.size(); ++gi) {
    const GarmentMesh& g = s.garments[gi];
    const std::string gp = "/garments/" + g.name;
    if (g.name.empty() || g.name.find('/') != std::string::npos || g.name == "." || !names.insert(g.name).second)
      fail(gp, "garment names must be unique, non-empty and without '/'");
    if (g.num_vertices <= 0 || seq.frames.garments[gi].rows() != static_cast<Eigen::Index>(T) * g.num_vertices)
      fail(gp + "/vertices", "shape does not match (T, N, 3)");
    check_coordinates(seq.frames.garments[gi].data(), seq.frames.garments[gi].size(), file, gp + "/vertices");
    check_faces(g.faces, g.num_vertices, file, gp + "/faces");
    if (g.uv.rows() != 3 * g.faces.rows()) fail(gp + "/uv", "must have 3 rows per face");
    check_finite(g.uv.data(), g.uv.size(), file, gp + "/uv");
    if (static_cast<Eigen::Index>(g.panel.size()) != g.faces.rows()) fail(gp + "/panel", "must have one id per face");
    for (int32_t p : g.panel)
      if (p < 0) fail(gp + "/panel", "negative panel ids (must be 0-based)");
    if (g.rest.rows() != 0 && g.rest.rows() != g.num_vertices) fail(gp + "/rest", "must have N rows");
    check_coordinates(g.rest.data(), g.rest.size(), file, gp + "/rest");
    if (!g.pin.empty() && static_cast<int>(g.pin.size()) != g.num_vertices) fail(gp + "/pin", "must have N weights");
    for (float w : g.pin)
      if (!(w >= 0.f && w <= 1.f)) fail(gp + "/pin", "weights must lie in [0, 1]");
    if (g.type.find_first_not_of(" \t\n") == std::string::npos) fail(gp, "attribute 'type' is empty");
    const auto& a = g.attributes;
    for (const float v : {a.tension_stiffness, a.bending_stiffness, a.mass, a.self_friction})
      if (!std::isfinite(v) || v < 0) fail(gp, "attributes must be finite and >= 0");
  }
  if (s.has_wind) {
    if (s.wind_rotation.rows() != T || s.wind_strength.size() != T) fail("/wind", "must have T rows");
    check_finite(s.wind_rotation.data(), s.wind_rotation.size(), file, "/wind/rotation");
    check_finite(s.wind_strength.data(), s.wind_strength.size(), file, "/wind/strength");
    for (int t = 0; t < T; ++t)
      if (std::abs(s.wind_rotation.row(t).cast<double>().norm() - 1.0) > kQuaternionTolerance)
        fail("/wind/rotation", "quaternion at frame " + std::to_string(t) + " is not unit");
  }
}

void write_sequence_contents(hid_t r, const Sequence& seq, const SequenceWriteOptions& options,
                             const std::string& path) {
  const SequenceInfo& s = seq.info;
  const uint64_t T = static_cast<uint64_t>(s.num_frames);
  h5::WriteOptions wo;
  wo.float64 = options.float64;
  wo.int64 = options.int64;
  wo.gzip = options.gzip;
  h5::WriteOptions plain = wo;
  plain.gzip = 0;
  h5::write_string_attr(r, "format", kFormatName);
  h5::write_int_attr(r, "version", kFormatVersion);
  h5::write_float_attr(r, "fps", s.fps);
  h5::write_string_attr(r, "up_axis", std::string(1, s.up_axis));
  h5::write_float_vector_attr(r, "gravity", {s.gravity.x(), s.gravity.y(), s.gravity.z()});
  h5::write_float_attr(r, "scale", s.scale);
  if (s.rest_frames > 0) h5::write_int_attr(r, "rest_frames", s.rest_frames);
  if (s.ramp_frames > 0) h5::write_int_attr(r, "ramp_frames", s.ramp_frames);
  if (s.wind_field_factor != 1.f) h5::write_float_attr(r, "wind_field_factor", s.wind_field_factor);
  if (s.stiffness_per_layer) h5::write_string_attr(r, "stiffness_groups", "per_layer");
  const h5::Where wb{path, "/body"};
  h5::Handle body = h5::create_group(r, "body", wb);
  h5::write_floats(body.get(), "vertices", seq.frames.body.data(),
                   {T, static_cast<uint64_t>(s.num_body_vertices), 3}, wo);
  h5::write_ints(body.get(), "faces", s.body_faces.data(), {static_cast<uint64_t>(s.body_faces.rows()), 3}, plain);
  if (options.write_translation) h5::write_floats(body.get(), "translation", s.translation.data(), {T, 3}, plain);
  h5::write_float_attr(body.get(), "friction", s.body_friction);
  h5::Handle garments = h5::create_group(r, "garments", h5::Where{path, "/garments"});
  std::vector<std::string> order;
  for (size_t gi = 0; gi < s.garments.size(); ++gi) {
    const GarmentMesh& g = s.garments[gi];
    order.push_back(g.name);
    h5::Handle gg = h5::create_group(garments.get(), g.name, h5::Where{path, "/garments/" + g.name});
    const uint64_t F = static_cast<uint64_t>(g.faces.rows()), N = static_cast<uint64_t>(g.num_vertices);
    h5::write_floats(gg.get(), "vertices", seq.frames.garments[gi].data(), {T, N, 3}, wo);
    h5::write_ints(gg.get(), "faces", g.faces.data(), {F, 3}, plain);
    h5::write_floats(gg.get(), "uv", g.uv.data(), {F, 3, 2}, plain);
    h5::write_ints(gg.get(), "panel", g.panel.data(), {F}, plain);
    if (g.rest.rows() > 0) h5::write_floats(gg.get(), "rest", g.rest.data(), {N, 3}, plain);
    if (!g.pin.empty()) h5::write_floats(gg.get(), "pin", g.pin.data(), {N}, plain);
    h5::write_string_attr(gg.get(), "type", g.type);
    h5::write_float_attr(gg.get(), "tension_stiffness", g.attributes.tension_stiffness);
    h5::write_float_attr(gg.get(), "bending_stiffness", g.attributes.bending_stiffness);
    h5::write_float_attr(gg.get(), "mass", g.attributes.mass);
    h5::write_float_attr(gg.get(), "self_friction", g.attributes.self_friction);
  }
  h5::write_string_array_attr(garments.get(), "order", order);
  if (s.has_wind) {
    h5::Handle w = h5::create_group(r, "wind", h5::Where{path, "/wind"});
    h5::write_floats(w.get(), "rotation", s.wind_rotation.data(), {T, 4}, plain);
    h5::write_floats(w.get(), "strength", s.wind_strength.data(), {T}, plain);
  }
}

void write_sequence(const std::string& path, const Sequence& seq, const SequenceWriteOptions& options) {
  validate_sequence(seq, path);
  h5::write_file(path, [&](hid_t f) { write_sequence_contents(f, seq, options, path); });
}

}  // namespace layersnet::dataset
