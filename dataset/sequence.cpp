// D-LAYERS-H5 sequence reader: every rule of the D-LAYERS-H5 format (docs/dlayers-h5.md) is
// checked here, in the order of the format's validator check_dlayers_h5.py, and the first violation is thrown.
#include "dataset/sequence.h"

#include "dataset/h5_guard.h"

#include <algorithm>
#include <cmath>
#include <set>
#include <sstream>

namespace layersnet::dataset {
namespace {

using h5::Kind;
using h5::Where;

Where at(const std::string& file, const std::string& path) { return Where{file, path}; }

std::string garment_path(const std::string& name) { return "/garments/" + name; }

// Reads a whole float dataset after checking kind and shape; values checked finite.
std::vector<float> read_float_array(hid_t loc, const std::string& name, const Where& where,
                                    const std::vector<int64_t>& want, h5::ArrayInfo* info_out = nullptr) {
  h5::Handle ds = h5::open_dataset(loc, name, where);
  h5::ArrayInfo info = h5::dataset_info(ds.get(), where);
  h5::check_array(info, Kind::kFloat, want, where);
  if (info_out) *info_out = info;
  return h5::read_floats(ds.get(), info, where);
}

std::vector<int64_t> read_int_array(hid_t loc, const std::string& name, const Where& where,
                                    const std::vector<int64_t>& want, h5::ArrayInfo* info_out) {
  h5::Handle ds = h5::open_dataset(loc, name, where);
  h5::ArrayInfo info = h5::dataset_info(ds.get(), where);
  h5::check_array(info, Kind::kInt, want, where);
  *info_out = info;
  return h5::read_ints(ds.get(), info, where);
}

// Shape of a (T, n, 3) position dataset without reading it.
h5::ArrayInfo position_shape(hid_t loc, const std::string& name, const Where& where) {
  h5::Handle ds = h5::open_dataset(loc, name, where);
  h5::ArrayInfo info = h5::dataset_info(ds.get(), where);
  h5::check_array(info, Kind::kFloat, {-1, -1, 3}, where);
  return info;
}

Faces read_faces(hid_t loc, const std::string& name, const Where& where, int64_t num_vertices) {
  h5::ArrayInfo info;
  std::vector<int64_t> f = read_int_array(loc, name, where, {-1, 3}, &info);
  if (info.dims[0] == 0) where.fail("has no faces");
  int64_t lo = f[0], hi = f[0], bad = 0;
  for (int64_t x : f) {
    lo = std::min(lo, x);
    hi = std::max(hi, x);
    bad += (x < 0 || x >= num_vertices);
  }
  if (bad)
    where.fail(std::to_string(bad) + " face indices out of range [0, " + std::to_string(num_vertices) +
               ") (min " + std::to_string(lo) + ", max " + std::to_string(hi) + ")");
  Faces faces(static_cast<Eigen::Index>(info.dims[0]), 3);
  for (size_t i = 0; i < f.size(); ++i) faces.data()[i] = static_cast<int32_t>(f[i]);
  return faces;
}

std::string number(double v) {
  std::ostringstream s;
  s << v;  // 6 significant digits: "1e+300", "-5"
  return s.str();
}

// Float attribute, finite also as the float32 the program computes with.
double read_float32_attr(hid_t obj, const std::string& name, const Where& where) {
  const double v = h5::read_float_attr(obj, name, where);
  if (!std::isfinite(static_cast<float>(v)))
    where.fail("attribute '" + name + "' = " + number(v) + " is not finite in float32");
  return v;
}

// A physical property (friction, stiffness, mass): finite in float32 and >= 0.
float read_property_attr(hid_t obj, const std::string& name, const Where& where) {
  const double v = read_float32_attr(obj, name, where);
  if (v < 0) where.fail("attribute '" + name + "' = " + number(v) + " is negative");
  return static_cast<float>(v);
}

// Every |coordinate| <= kMaxSceneCoordinate; the message names the first frame and vertex
// beyond it (frames counted from `first_frame`, rows of `rows_per_frame`).
void check_extent(const std::vector<float>& v, const Where& where, int first_frame = 0, int64_t rows_per_frame = 0) {
  for (size_t i = 0; i < v.size(); ++i)
    if (std::abs(v[i]) > kMaxSceneCoordinate) {
      const int64_t row = static_cast<int64_t>(i / 3);
      const std::string at_row = rows_per_frame > 0 ? "frame " + std::to_string(first_frame + row / rows_per_frame) +
                                                          ", vertex " + std::to_string(row % rows_per_frame)
                                                    : "row " + std::to_string(row);
      where.fail("holds the coordinate " + number(v[i]) + " at " + at_row + ", beyond the scene extent +-" +
                 std::to_string(static_cast<int>(kMaxSceneCoordinate)) +
                 " units (damaged data, or not in scene units?)");
    }
}

Points to_points(std::vector<float>&& v) {
  Points p(static_cast<Eigen::Index>(v.size() / 3), 3);
  std::copy(v.begin(), v.end(), p.data());
  return p;
}

// Signed volume of the closed-ish body mesh (centred for accuracy); < 0 means the faces
// are oriented inward.
double signed_volume(const Points& v, const Faces& f) {
  const Eigen::Vector3d c = v.cast<double>().colwise().mean();
  double vol = 0;
  for (Eigen::Index i = 0; i < f.rows(); ++i) {
    const Eigen::Vector3d a = v.row(f(i, 0)).cast<double>().transpose() - c;
    const Eigen::Vector3d b = v.row(f(i, 1)).cast<double>().transpose() - c;
    const Eigen::Vector3d d = v.row(f(i, 2)).cast<double>().transpose() - c;
    vol += a.dot(b.cross(d));
  }
  return vol / 6.0;
}

void read_root_attributes(hid_t file, SequenceInfo& info) {
  const Where root = at(info.path, "/");
  const std::string format = h5::read_string_attr(file, "format", root);
  if (format != kFormatName)
    root.fail("attribute 'format' is '" + format + "', must be 'dlayers-h5'");
  const int64_t version = h5::read_int_attr(file, "version", root);
  if (version != kFormatVersion)
    root.fail("attribute 'version' is " + std::to_string(version) +
              ", must be 1 (this reader knows format version 1 only)");
  info.fps = static_cast<float>(read_float32_attr(file, "fps", root));
  if (!(info.fps > 0)) root.fail("attribute 'fps' must be > 0, is " + std::to_string(info.fps));
  const std::string up = h5::read_string_attr(file, "up_axis", root);
  if (up != "z" && up != "y") root.fail("attribute 'up_axis' is '" + up + "', must be 'z' or 'y'");
  info.up_axis = up[0];
  info.scale = static_cast<float>(read_float32_attr(file, "scale", root));
  if (!(info.scale > 0)) root.fail("attribute 'scale' must be > 0, is " + std::to_string(info.scale));
  const std::vector<double> g = h5::read_float_vector_attr(file, "gravity", 3, root);
  for (const double c : g)
    if (!std::isfinite(static_cast<float>(c))) root.fail("attribute 'gravity' is not finite in float32");
  info.gravity = Eigen::Vector3f(static_cast<float>(g[0]), static_cast<float>(g[1]), static_cast<float>(g[2]));
  const double norm = std::sqrt(g[0] * g[0] + g[1] * g[1] + g[2] * g[2]);
  if (norm > 0) {
    const double cosang = -g[info.up_axis == 'z' ? 2 : 1] / norm;
    if (cosang < std::cos(1.0 * M_PI / 180.0))
      root.fail("attribute 'gravity' (" + std::to_string(g[0]) + ", " + std::to_string(g[1]) + ", " +
                std::to_string(g[2]) + ") does not point along -" + up + " (up_axis)");
  }
  for (auto [name, value] : {std::pair<const char*, int*>{"rest_frames", &info.rest_frames}, {"ramp_frames", &info.ramp_frames}})
    if (h5::has_attr(file, name)) {
      const double f = h5::read_float_attr(file, name, root);
      if (!(f >= 0 && f <= INT32_MAX)) root.fail(std::string("attribute '") + name + "' must be >= 0, is " + std::to_string(f));
      *value = static_cast<int>(std::lround(f));
    }
  if (h5::has_attr(file, "wind_field_factor")) {
    info.wind_field_factor = static_cast<float>(read_float32_attr(file, "wind_field_factor", root));
    if (!(info.wind_field_factor >= 0))
      root.fail("attribute 'wind_field_factor' must be >= 0, is " + std::to_string(info.wind_field_factor));
  }
  if (h5::has_attr(file, "stiffness_groups")) {
    const std::string rule = h5::read_string_attr(file, "stiffness_groups", root);
    if (rule != "per_layer" && rule != "outer_max")
      root.fail("attribute 'stiffness_groups' must be \"per_layer\" or \"outer_max\", is \"" + rule + "\"");
    info.stiffness_per_layer = rule == "per_layer";
  }
}

void read_body(hid_t file, SequenceInfo& info) {
  h5::Handle body = h5::open_group(file, "body", at(info.path, "/body"));
  const Where wv = at(info.path, "/body/vertices");
  const h5::ArrayInfo vi = position_shape(body.get(), "vertices", wv);
  info.num_frames = static_cast<int>(std::min<uint64_t>(vi.dims[0], INT32_MAX));
  if (vi.dims[0] < 3) wv.fail("T = " + std::to_string(vi.dims[0]) + " frames, must be >= 3");
  if (vi.dims[1] == 0) wv.fail("has no vertices");
  if (vi.dims[1] > INT32_MAX) wv.fail("has too many vertices");
  info.num_body_vertices = static_cast<int>(vi.dims[1]);
  info.body_faces = read_faces(body.get(), "faces", at(info.path, "/body/faces"), info.num_body_vertices);
  const int T = info.num_frames;
  if (h5::has_link(body.get(), "translation")) {
    std::vector<float> translation = read_float_array(body.get(), "translation", at(info.path, "/body/translation"), {T, 3});
    check_extent(translation, at(info.path, "/body/translation"), 0, 1);
    info.translation = to_points(std::move(translation));
    info.has_translation = true;
  } else {
    info.translation = Points::Zero(T, 3);
  }
  info.body_friction = read_property_attr(body.get(), "friction", at(info.path, "/body"));
}

GarmentMesh read_garment(hid_t garments, const std::string& name, SequenceInfo& info) {
  const std::string gp = garment_path(name);
  h5::Handle g = h5::open_group(garments, name, at(info.path, gp));
  GarmentMesh m;
  m.name = name;
  const Where wv = at(info.path, gp + "/vertices");
  const h5::ArrayInfo vi = position_shape(g.get(), "vertices", wv);
  if (vi.dims[0] != static_cast<uint64_t>(info.num_frames))
    wv.fail("has " + std::to_string(vi.dims[0]) + " frames but /body/vertices has " +
            std::to_string(info.num_frames));
  if (vi.dims[1] == 0) wv.fail("has no vertices");
  if (vi.dims[1] > INT32_MAX) wv.fail("has too many vertices");
  m.num_vertices = static_cast<int>(vi.dims[1]);
  m.faces = read_faces(g.get(), "faces", at(info.path, gp + "/faces"), m.num_vertices);
  const int64_t F = m.faces.rows();
  std::vector<float> uv = read_float_array(g.get(), "uv", at(info.path, gp + "/uv"), {F, 3, 2});
  m.uv.resize(F * 3, 2);
  std::copy(uv.begin(), uv.end(), m.uv.data());
  const Where wp = at(info.path, gp + "/panel");
  h5::ArrayInfo pinfo;
  std::vector<int64_t> panel = read_int_array(g.get(), "panel", wp, {F}, &pinfo);
  int64_t negative = 0;
  for (int64_t p : panel) {
    negative += p < 0;
    if (p > INT32_MAX) wp.fail("panel id " + std::to_string(p) + " is beyond int32 range");
  }
  if (negative) wp.fail(std::to_string(negative) + " negative panel ids (must be 0-based)");
  m.panel.assign(panel.begin(), panel.end());
  if (h5::has_link(g.get(), "rest")) {
    std::vector<float> rest = read_float_array(g.get(), "rest", at(info.path, gp + "/rest"), {m.num_vertices, 3});
    check_extent(rest, at(info.path, gp + "/rest"));
    m.rest = to_points(std::move(rest));
  }
  if (h5::has_link(g.get(), "pin")) {
    const Where wpin = at(info.path, gp + "/pin");
    m.pin = read_float_array(g.get(), "pin", wpin, {m.num_vertices});
    const auto bad = std::find_if(m.pin.begin(), m.pin.end(), [](float w) { return !(w >= 0.f && w <= 1.f); });
    if (bad != m.pin.end())
      wpin.fail("weight " + std::to_string(*bad) + " of vertex " + std::to_string(bad - m.pin.begin()) +
                " is outside [0, 1]");
  }
  const Where wg = at(info.path, gp);
  m.type = h5::read_string_attr(g.get(), "type", wg);
  if (m.type.find_first_not_of(" \t\n") == std::string::npos) wg.fail("attribute 'type' is empty");
  auto& a = m.attributes;
  a.tension_stiffness = read_property_attr(g.get(), "tension_stiffness", wg);
  a.bending_stiffness = read_property_attr(g.get(), "bending_stiffness", wg);
  a.mass = read_property_attr(g.get(), "mass", wg);
  a.self_friction = read_property_attr(g.get(), "self_friction", wg);
  return m;
}

void read_garments(hid_t file, SequenceInfo& info) {
  const Where wg = at(info.path, "/garments");
  h5::Handle gr = h5::open_group(file, "garments", wg);
  std::vector<std::string> groups;
  for (const std::string& name : h5::member_names(gr.get(), wg)) {
    h5::ObjectType t;
    h5::Handle o = h5::open_object(gr.get(), name, at(info.path, garment_path(name)), &t);
    if (t != h5::ObjectType::kGroup)
      at(info.path, garment_path(name)).fail("must be a group (only garment groups belong under /garments)");
    groups.push_back(name);
  }
  if (groups.empty()) wg.fail("has no garment (at least one is required)");
  const std::vector<std::string> order = h5::read_string_array_attr(gr.get(), "order", wg);
  std::set<std::string> seen;
  for (const auto& n : order)
    if (!seen.insert(n).second) wg.fail("attribute 'order' lists '" + n + "' more than once");
  for (const auto& n : order)
    if (std::find(groups.begin(), groups.end(), n) == groups.end())
      wg.fail("attribute 'order' names ['" + n + "'] which are not garment groups");
  for (const auto& n : groups)
    if (!seen.count(n)) wg.fail("garment groups ['" + n + "'] are not listed in attribute 'order'");
  for (const auto& n : order) info.garments.push_back(read_garment(gr.get(), n, info));
}

void read_wind(hid_t file, SequenceInfo& info) {
  if (!h5::has_link(file, "wind")) return;
  h5::Handle w = h5::open_group(file, "wind", at(info.path, "/wind"));
  const int T = info.num_frames;
  const Where wr = at(info.path, "/wind/rotation");
  std::vector<float> q = read_float_array(w.get(), "rotation", wr, {T, 4});
  info.wind_rotation.resize(T, 4);
  std::copy(q.begin(), q.end(), info.wind_rotation.data());
  int bad = 0, first_bad = -1;
  for (int t = 0; t < T; ++t) {
    const double n = info.wind_rotation.row(t).cast<double>().norm();
    if (std::abs(n - 1.0) > kQuaternionTolerance && bad++ == 0) first_bad = t;
  }
  if (bad)
    wr.fail(std::to_string(bad) + " quaternions are not unit within 0.001 (first at frame " +
            std::to_string(first_bad) + ", norm " +
            std::to_string(info.wind_rotation.row(first_bad).norm()) + ")");
  std::vector<float> s = read_float_array(w.get(), "strength", at(info.path, "/wind/strength"), {T});
  info.wind_strength = Eigen::Map<Eigen::VectorXf>(s.data(), T);
  info.has_wind = true;
}

}  // namespace

int64_t SequenceInfo::total_garment_vertices() const {
  int64_t n = 0;
  for (const auto& g : garments) n += g.num_vertices;
  return n;
}

std::vector<Eigen::Index> SequenceInfo::pinned_rows() const {
  std::vector<Eigen::Index> rows;
  Eigen::Index offset = 0;
  for (const GarmentMesh& g : garments) {
    for (int v = 0; v < g.num_vertices; ++v)
      if (g.pinned(v)) rows.push_back(offset + v);
    offset += g.num_vertices;
  }
  return rows;
}

int64_t SequenceInfo::bytes_per_frame() const {
  return (num_body_vertices + total_garment_vertices()) * 3 * static_cast<int64_t>(sizeof(float));
}

int64_t FrameWindow::bytes() const {
  int64_t b = body.size();
  for (const auto& g : garments) b += g.size();
  return b * static_cast<int64_t>(sizeof(float));
}

SequenceInfo mirrored(SequenceInfo info) {
  const auto rewind = [](Faces& faces) { faces.col(1).swap(faces.col(2)); };
  rewind(info.body_faces);
  mirror_points(info.translation);
  info.gravity.x() = -info.gravity.x();
  for (GarmentMesh& g : info.garments) {
    rewind(g.faces);
    for (Eigen::Index f = 0; f < g.faces.rows(); ++f) g.uv.row(3 * f + 1).swap(g.uv.row(3 * f + 2));  // corners follow
    mirror_points(g.rest);
  }
  // The mirrored rotation is M R M, M = diag(−1, 1, 1): (w, x, y, z) → (w, x, −y, −z). It maps the
  // wind's reference axis z (which M keeps) to M times the old direction.
  if (info.wind_rotation.rows() > 0) {
    info.wind_rotation.col(2) *= -1.f;
    info.wind_rotation.col(3) *= -1.f;
  }
  return info;
}

void mirror_points(Points& points) { points.col(0) *= -1.f; }

void mirror_positions(FrameWindow& frames) {
  mirror_points(frames.body);
  for (Points& g : frames.garments) mirror_points(g);
}

void mirror(Sequence& seq) {
  seq.info = mirrored(std::move(seq.info));
  mirror_positions(seq.frames);
}

SequenceFile::SequenceFile(const std::string& path) {
  h5::guard_file(path, [&] { SequenceFile(path).read_all(); });  // every read this program makes of it
  info_.path = path;
  file_ = h5::open_file(path);
  load();
}

SequenceFile::SequenceFile(std::span<const uint8_t> image, const std::string& name) {
  h5::guard_image(image, name, [&] { SequenceFile(image, name).read_all(); });
  info_.path = name;
  file_ = h5::open_file_image(image, name);
  load();
}

SequenceFile::~SequenceFile() = default;
SequenceFile::SequenceFile(SequenceFile&&) noexcept = default;
SequenceFile& SequenceFile::operator=(SequenceFile&&) noexcept = default;

void SequenceFile::load() {
  const hid_t f = file_.get();
  read_root_attributes(f, info_);
  read_body(f, info_);
  read_garments(f, info_);
  read_wind(f, info_);
  // Orientation needs one frame of body positions (as the validator: frame 0).
  const FrameWindow first = [&] {
    h5::Handle body = h5::open_group(f, "body", at(info_.path, "/body"));
    const Where wv = at(info_.path, "/body/vertices");
    h5::Handle ds = h5::open_dataset(body.get(), "vertices", wv);
    FrameWindow w;
    w.body = to_points(h5::read_floats(ds.get(), h5::dataset_info(ds.get(), wv), wv, 0, 1));
    return w;
  }();
  const double vol = signed_volume(first.body, info_.body_faces);
  if (vol < 0)
    at(info_.path, "/body/faces")
        .fail("faces are oriented inward (signed volume " + std::to_string(vol) +
              " < 0 at frame 0); must be counter-clockwise seen from outside");
}

FrameWindow SequenceFile::read_frames(int first, int count) const {
  if (first < 0 || count < 0 || first + count > info_.num_frames)
    throw DatasetError(info_.path, "/", "frames [" + std::to_string(first) + ", " +
                                            std::to_string(first + count) + ") requested, the file has " +
                                            std::to_string(info_.num_frames));
  FrameWindow w;
  w.first = first;
  w.count = count;
  const hid_t f = file_.get();
  auto read = [&](const std::string& path) {
    const Where where = at(info_.path, path);
    h5::Handle ds = h5::open_dataset(f, path, where);
    const h5::ArrayInfo shape = h5::dataset_info(ds.get(), where);
    std::vector<float> v = h5::read_floats(ds.get(), shape, where, first, count);
    check_extent(v, where, first, static_cast<int64_t>(shape.dims[1]));
    return to_points(std::move(v));
  };
  w.body = read("/body/vertices");
  for (const auto& g : info_.garments) w.garments.push_back(read(garment_path(g.name) + "/vertices"));
  return w;
}

Sequence SequenceFile::read_all() const {
  Sequence s;
  s.info = info_;
  s.frames = read_frames(0, info_.num_frames);
  return s;
}

Sequence read_sequence(const std::string& path) { return SequenceFile(path).read_all(); }

}  // namespace layersnet::dataset
