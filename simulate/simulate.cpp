// A user's scene: reading, checks, the rollout from rest and the outputs (see simulate.h).
#include "simulate/simulate.h"

#include "simulate/wind.h"

#include "dataset/manifest.h"
#include "dataset/mesh_io.h"
#include "dataset/neighbours.h"
#include "dataset/patches.h"
#include "dataset/pin_carry.h"
#include "eval/render.h"

#include <Eigen/Geometry>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <set>
#include <sstream>
#include <omp.h>
#include <unistd.h>

namespace layersnet::eval {
namespace fs = std::filesystem;
using dataset::Faces;

namespace {

std::string fixed(double v, int digits = 2) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.*f", digits, v);
  return buf;
}

std::string vec_text(const Eigen::RowVector3f& v) {
  return "(" + fixed(v.x()) + ", " + fixed(v.y()) + ", " + fixed(v.z()) + ")";
}

// Input axes and units -> the model's: x_model = factor * R x_input.
struct UnitConversion {
  float factor = 1.f;
  Eigen::Matrix3f rotation = Eigen::Matrix3f::Identity();
  bool identity() const { return factor == 1.f && rotation.isIdentity(); }
  Points to_model(const Points& x) const {
    if (identity()) return x;
    return factor * (x * rotation.transpose());
  }
  Points to_input(const Eigen::Ref<const Points>& x) const {
    if (identity()) return x;
    return (x * rotation) / factor;
  }
};

UnitConversion conversion(float scale, char up_axis) {
  UnitConversion c;
  c.factor = kModelScale / scale;
  if (up_axis == 'y') c.rotation << 1, 0, 0, 0, 0, -1, 0, 1, 0;  // (x, y, z) -> (x, -z, y)
  return c;
}

// ---- body

struct BodyMotion {
  std::string source;  // file or folder for messages
  std::vector<Points> frames;  // (K,) each (B, 3), input units
  Faces faces;
  Points translation;  // (K, 3) model units, 0 rows = estimate
  float fps = 30.f, scale = kModelScale;
  char up_axis = 'z';
  float friction = 60.f;
};

void check_same_topology(const std::string& file, Eigen::Index rows, const std::string& first_file,
                         Eigen::Index first_rows) {
  if (rows != first_rows)
    throw SimulateError(file + ": has " + std::to_string(rows) + " vertices but " + first_file + " has " +
                        std::to_string(first_rows) +
                        ": every body frame needs the same mesh (export the animation without modifiers that "
                        "change the vertex count, e.g. apply Decimate/Remesh before baking)");
}

BodyMotion read_body(const SceneInputs& in) {
  const BodyInput& b = in.body;
  const int sources = !b.obj_folder.empty() + !b.pc2.empty() + !b.h5.empty();
  if (sources != 1)
    throw SimulateError("give the body motion once: a folder of OBJ frames, a PC2 with its topology OBJ, "
                        "or a D-LAYERS-H5 file");
  BodyMotion m;
  m.fps = in.fps;
  m.scale = in.scale;
  m.up_axis = in.up_axis;
  if (!b.obj_folder.empty()) {
    m.source = b.obj_folder;
    if (!fs::is_directory(b.obj_folder))
      throw SimulateError(b.obj_folder + ": is not a folder; the body motion is a folder of OBJ files, one per frame");
    std::vector<fs::path> files;
    for (const auto& e : fs::directory_iterator(b.obj_folder))
      if (e.is_regular_file() && e.path().extension() == ".obj") files.push_back(e.path());
    std::sort(files.begin(), files.end());
    if (in.max_frames > 0 && static_cast<int>(files.size()) > in.max_frames) files.resize(in.max_frames);
    if (files.empty()) throw SimulateError(b.obj_folder + ": holds no .obj files; export one OBJ per body frame");
    for (const fs::path& f : files) {
      dataset::ObjMesh mesh = dataset::read_obj(f.string());
      if (m.frames.empty())
        m.faces = mesh.faces;
      else
        check_same_topology(f.string(), mesh.positions.rows(), files.front().string(), m.frames.front().rows());
      m.frames.push_back(std::move(mesh.positions));
    }
  } else if (!b.pc2.empty()) {
    m.source = b.pc2;
    if (b.topology.empty())
      throw SimulateError(b.pc2 + ": a PC2 holds positions only; give its mesh with --body-topology OBJ");
    dataset::ObjMesh topo = dataset::read_obj(b.topology);
    dataset::PointCache cache = dataset::read_pc2(b.pc2);
    check_same_topology(b.pc2, cache.frames.front().rows(), b.topology, topo.positions.rows());
    m.faces = topo.faces;
    m.frames = std::move(cache.frames);
    if (in.max_frames > 0 && static_cast<int>(m.frames.size()) > in.max_frames) m.frames.resize(in.max_frames);
  } else {
    m.source = b.h5;
    const dataset::Sequence seq = dataset::read_sequence(b.h5);
    const int K = in.max_frames > 0 ? std::min(in.max_frames, seq.info.num_frames) : seq.info.num_frames;
    for (int t = 0; t < K; ++t) m.frames.push_back(seq.body_at(t));
    m.faces = seq.info.body_faces;
    m.fps = seq.info.fps;
    m.scale = seq.info.scale;
    m.up_axis = seq.info.up_axis;
    m.friction = seq.info.body_friction;
    if (seq.info.has_translation) m.translation = seq.info.translation.topRows(K);
  }
  if (m.frames.size() < 2)
    throw SimulateError(m.source + ": the body motion has " + std::to_string(m.frames.size()) +
                        " frame; at least 2 are needed (the first is the rest pose the garments are posed on)");
  return m;
}

// The body's extent along the up axis says whether the units are right.
void check_units(const BodyMotion& body, const Points& first_frame_model) {
  const float height_units = (first_frame_model.col(2).maxCoeff() - first_frame_model.col(2).minCoeff()) /
                             (kModelScale / body.scale);
  const float height_m = height_units / body.scale;
  if (height_m >= 0.5f && height_m <= 3.f) return;
  std::string fix;
  if (height_units >= 0.5f && height_units <= 3.f)
    fix = "the files look like metres: pass --scale 1";
  else if (height_units >= 50.f && height_units <= 300.f)
    fix = "the files look like centimetres: pass --scale 100";
  else if (height_units >= 500.f && height_units <= 3000.f)
    fix = "the files look like millimetres: pass --scale 1000";
  else if (height_units >= 5.f && height_units <= 30.f)
    fix = "the files look like the x10 convention: pass --scale 10";
  else
    fix = "check the export's units and --up (the body's height is measured along the up axis)";
  throw SimulateError(body.source + ": the body is " + fixed(height_units) + " units tall along " +
                      std::string(1, body.up_axis) + ", which is " + fixed(height_m, 3) + " m at --scale " +
                      fixed(body.scale, 3) +
                      " (input units per metre; the default 10 is the D-LAYERS x10 convention, where a person is "
                      "about 18 units tall); a person is 0.5 to 3 m tall: " + fix);
}

// ---- garments

std::vector<int32_t> read_pin_file(const std::string& path, int num_vertices, const std::string& garment) {
  std::ifstream in(path);
  if (!in) throw SimulateError(path + ": the pin file of " + garment + " cannot be opened (check the path)");
  std::vector<int32_t> pins;
  std::string line;
  int line_no = 0;
  while (std::getline(in, line)) {
    ++line_no;
    line = line.substr(0, line.find('#'));
    std::replace(line.begin(), line.end(), ',', ' ');
    std::stringstream s(line);
    std::string word;
    while (s >> word) {
      long v = -1;
      try {
        size_t used = 0;
        v = std::stol(word, &used);
        if (used != word.size()) v = -1;
      } catch (const std::exception&) {
      }
      if (v < 0 || v >= num_vertices)
        throw SimulateError(path + ": line " + std::to_string(line_no) + ": '" + word +
                            "' is not a vertex of " + garment + " (0-based indices below " +
                            std::to_string(num_vertices) + ")");
      pins.push_back(static_cast<int32_t>(v));
    }
  }
  std::sort(pins.begin(), pins.end());
  pins.erase(std::unique(pins.begin(), pins.end()), pins.end());
  if (pins.empty()) throw SimulateError(path + ": holds no vertex index; list the pinned vertices, 0-based");
  return pins;
}

// The open border loop highest along z (model axes): vertices of edges used by one face,
// grouped into connected loops.
std::vector<int32_t> top_ring(const Points& x, const Faces& faces, const std::string& garment) {
  std::map<std::pair<int32_t, int32_t>, int> uses;
  for (Eigen::Index f = 0; f < faces.rows(); ++f)
    for (int c = 0; c < 3; ++c) {
      const int32_t a = faces(f, c), b = faces(f, (c + 1) % 3);
      ++uses[{std::min(a, b), std::max(a, b)}];
    }
  std::map<int32_t, std::vector<int32_t>> border;  // vertex -> border neighbours
  for (const auto& [edge, n] : uses)
    if (n == 1) {
      border[edge.first].push_back(edge.second);
      border[edge.second].push_back(edge.first);
    }
  if (border.empty())
    throw SimulateError(garment + ": pins=top-ring needs an open border, but the mesh is closed; give a pin file");
  std::set<int32_t> seen;
  std::vector<int32_t> best;
  double best_height = -1e30;
  for (const auto& [start, unused] : border) {
    if (seen.count(start)) continue;
    std::vector<int32_t> loop, stack{start};
    seen.insert(start);
    while (!stack.empty()) {
      const int32_t v = stack.back();
      stack.pop_back();
      loop.push_back(v);
      for (int32_t w : border[v])
        if (seen.insert(w).second) stack.push_back(w);
    }
    double height = 0;
    for (int32_t v : loop) height += x(v, 2);
    height /= static_cast<double>(loop.size());
    if (height > best_height) best_height = height, best = loop;
  }
  std::sort(best.begin(), best.end());
  return best;
}

// The garment must be dressed on the body's first frame: its centroid within the body's
// bounds, grown by a quarter of the body's height.
void check_around_body(const std::string& file, const Points& garment, const Points& body) {
  const Eigen::RowVector3f lo = body.colwise().minCoeff(), hi = body.colwise().maxCoeff();
  const float margin = 0.25f * (hi.z() - lo.z());
  const Eigen::RowVector3f centroid = garment.colwise().mean();
  const Eigen::RowVector3f outside =
      (lo.array() - margin - centroid.array()).max(centroid.array() - hi.array() - margin).max(0.f).matrix();
  if (outside.norm() > 0)
    throw SimulateError(file + ": the garment's centroid " + vec_text(centroid) + " lies " + fixed(outside.norm()) +
                        " model units outside the body's first frame (bounds " + vec_text(lo) + " to " +
                        vec_text(hi) +
                        "): pose the garment on the body's first frame, exported from the same scene with the same "
                        "units (--scale) and up axis (--up)");
}

// A garment has a shape: its vertices do not all sit at one point (a mesh exported without
// its transforms, or with every vertex snapped together, would be simulated as a point).
void check_garment_shape(const std::string& file, const Points& garment, const Points& body) {
  const float height = body.col(2).maxCoeff() - body.col(2).minCoeff();
  const float extent = (garment.colwise().maxCoeff() - garment.colwise().minCoeff()).maxCoeff();
  if (!(extent > 1e-5f * height))
    throw SimulateError(file + ": all " + std::to_string(garment.rows()) + " vertices lie at one point " +
                        vec_text(garment.row(0)) +
                        " (model units): the garment has no shape; export the mesh with its vertex positions "
                        "(apply its transforms and modifiers) posed on the body's first frame");
}

// Two layers are two garments: the same file, or the same vertices, given twice would put one
// layer exactly on the other.
void check_distinct_layers(const std::string& first_file, const Points& first, const std::string& file,
                           const Points& garment) {
  std::error_code ec;
  const bool same_file = fs::equivalent(first_file, file, ec) && !ec;
  const bool same_vertices = first.rows() == garment.rows() && first == garment;
  if (same_file || same_vertices)
    throw SimulateError(file + ": " + (same_file ? "is the same file as " : "has the same vertices as ") + first_file +
                        ", given as an earlier layer: each --garment is its own layer, from the innermost to the "
                        "outermost; give each layer's own OBJ once");
}

// An outer layer lies outside the inner one: where the two are close, each outer vertex lies on
// the outward side of its nearest inner vertex, outward being the body's normal there.
void check_layer_order(const std::string& inner_file, const Points& inner, const std::string& outer_file,
                       const Points& outer, const Points& body, const Faces& body_faces) {
  const float height = body.col(2).maxCoeff() - body.col(2).minCoeff();
  const dataset::NearestBody outer_to_inner = dataset::nearest_body(outer, inner);
  const dataset::NearestBody inner_to_body = dataset::nearest_body(inner, body);
  const Points normals = dataset::vertex_normals(body, body_faces);
  int near = 0, inside = 0;
  for (Eigen::Index v = 0; v < outer.rows(); ++v) {
    if (outer_to_inner.distance[v] > 0.05f * height) continue;
    ++near;
    const int32_t i = outer_to_inner.index[v];
    if ((outer.row(v) - inner.row(i)).dot(normals.row(inner_to_body.index[i])) < 0) ++inside;
  }
  if (near >= 10 && inside * 2 > near)
    throw SimulateError(outer_file + ": lies inside " + inner_file + " (" + std::to_string(inside) + " of its " +
                        std::to_string(near) + " vertices near " + inner_file +
                        " are on the body's side of it): garments are given from the innermost to the outermost, so "
                        "the order is probably wrong; swap the --garment options");
}

// Unique, HDF5-safe garment names.
std::string garment_name(const GarmentInput& g, std::set<std::string>& used) {
  std::string base = g.name.empty() ? fs::path(g.obj).stem().string() : g.name;
  for (char& c : base)
    if (c == '/' || c == ' ') c = '_';
  if (base.empty() || base == "." || base == "..") base = "garment";
  std::string name = base;
  for (int k = 2; !used.insert(name).second; ++k) name = base + "_" + std::to_string(k);
  return name;
}

}  // namespace

GarmentInput parse_garment_spec(const std::string& spec) {
  GarmentInput g;
  const auto parts = split(spec, ',');
  if (parts.empty() || parts[0].empty()) throw SimulateError("--garment '" + spec + "': give the garment's OBJ file");
  g.obj = parts[0];
  for (size_t i = 1; i < parts.size(); ++i) {
    const auto eq = parts[i].find('=');
    const std::string key = trim(parts[i].substr(0, eq)), value = eq == std::string::npos ? "" : trim(parts[i].substr(eq + 1));
    const std::string what = "--garment " + spec + ": " + key;
    if (eq == std::string::npos || value.empty())
      throw SimulateError("--garment " + spec + ": '" + parts[i] + "' is not key=value");
    auto attribute = [&](float& slot) {
      slot = parse_number(value, what);
      if (slot < 0) throw SimulateError(what + " must be >= 0");
    };
    if (key == "name") g.name = value;
    else if (key == "type") g.type = value;
    else if (key == "pins") g.pins = value;
    else if (key == "tension") attribute(g.attributes.tension_stiffness);
    else if (key == "bending") attribute(g.attributes.bending_stiffness);
    else if (key == "mass") attribute(g.attributes.mass);
    else if (key == "friction") attribute(g.attributes.self_friction);
    else
      throw SimulateError("--garment " + spec + ": unknown key '" + key +
                          "'; keys are name, type, pins, tension, bending, mass, friction");
  }
  return g;
}

Points estimated_root_translation(const Points& body, int num_body_vertices) {
  const Eigen::Index T = body.rows() / num_body_vertices;
  Points root(T, 3);
  for (Eigen::Index t = 0; t < T; ++t) root.row(t) = body.middleRows(t * num_body_vertices, num_body_vertices).colwise().mean();
  return root;
}

Points Scene::to_input_units(const Eigen::Ref<const Points>& x) const { return conversion(scale, up_axis).to_input(x); }

Scene build_scene(const SceneInputs& in) {
  if (in.garments.empty()) throw SimulateError("give at least one --garment OBJ");
  if (!(in.fps > 0) || !std::isfinite(in.fps)) throw SimulateError("--fps must be a finite number > 0");
  if (!(in.scale > 0) || !std::isfinite(in.scale)) throw SimulateError("--scale must be a finite number > 0");
  if (in.up_axis != 'z' && in.up_axis != 'y') throw SimulateError("--up must be z or y");
  BodyMotion body = read_body(in);
  const UnitConversion units = conversion(body.scale, body.up_axis);
  const int K = static_cast<int>(body.frames.size());
  const int B = static_cast<int>(body.frames.front().rows());
  const int T = K + kSceneRestFrames - 1;
  Scene scene;
  scene.body_frames = K;
  scene.scale = body.scale;
  scene.up_axis = body.up_axis;
  dataset::Sequence& seq = scene.sequence;
  dataset::SequenceInfo& info = seq.info;
  info.path = "the simulated scene";
  info.pins_recorded = false;
  info.fps = body.fps;
  info.scale = kModelScale;
  info.up_axis = 'z';
  info.num_frames = T;
  info.num_body_vertices = B;
  info.body_faces = body.faces;
  info.body_friction = body.friction;
  info.rest_frames = kSceneRestFrames;
  seq.frames.first = 0;
  seq.frames.count = T;
  seq.frames.body.resize(static_cast<Eigen::Index>(T) * B, 3);
  for (int t = 0; t < T; ++t) {
    const int k = std::max(0, t - (kSceneRestFrames - 1));
    seq.frames.body.middleRows(static_cast<Eigen::Index>(t) * B, B) = units.to_model(body.frames[k]);
  }
  const Points body0 = seq.body_at(0);
  check_units(body, body0);
  if (body.translation.rows() == K) {
    const Points root = units.to_model(body.translation);
    info.translation.resize(T, 3);
    for (int t = 0; t < T; ++t) info.translation.row(t) = root.row(std::max(0, t - (kSceneRestFrames - 1)));
  } else {
    info.translation = estimated_root_translation(seq.frames.body, B);
  }
  info.has_translation = true;

  std::set<std::string> names;
  std::vector<Points> starts;
  for (const GarmentInput& gi : in.garments) {
    dataset::ObjMesh obj = dataset::read_obj(gi.obj);
    if (!obj.has_uv())
      throw SimulateError(gi.obj + ": has no texture coordinates (vt) on every face; garments need UVs to be cut "
                                   "into patches: unwrap the garment (Blender: UV > Unwrap, or its sewing pattern) "
                                   "and export the OBJ with UV coordinates");
    dataset::GarmentMesh g;
    g.name = garment_name(gi, names);
    g.type = gi.type.empty() ? "garment" : gi.type;
    g.num_vertices = static_cast<int>(obj.positions.rows());
    g.faces = obj.faces;
    g.uv = obj.uv;
    g.panel = dataset::uv_islands(g.faces, g.uv);
    g.rest = units.to_model(obj.positions);
    g.attributes = gi.attributes;
    check_garment_shape(gi.obj, g.rest, body0);
    for (size_t i = 0; i < starts.size(); ++i) check_distinct_layers(in.garments[i].obj, starts[i], gi.obj, g.rest);
    check_around_body(gi.obj, g.rest, body0);
    if (!starts.empty()) check_layer_order(in.garments[starts.size() - 1].obj, starts.back(), gi.obj, g.rest, body0, info.body_faces);
    std::vector<int32_t> pins;
    if (gi.pins == "top-ring")
      pins = top_ring(g.rest, g.faces, gi.obj);
    else if (!gi.pins.empty())
      pins = read_pin_file(gi.pins, g.num_vertices, gi.obj);
    if (!pins.empty()) {
      g.pin.assign(static_cast<size_t>(g.num_vertices), 0.f);
      for (int32_t v : pins) g.pin[static_cast<size_t>(v)] = 1.f;
    }
    scene.pins.push_back(std::move(pins));
    Points frames(static_cast<Eigen::Index>(T) * g.num_vertices, 3);
    for (int t = 0; t < T; ++t) frames.middleRows(static_cast<Eigen::Index>(t) * g.num_vertices, g.num_vertices) = g.rest;
    starts.push_back(g.rest);
    seq.frames.garments.push_back(std::move(frames));
    info.garments.push_back(std::move(g));
  }

  const std::vector<WindRow> wind = read_wind(in.wind);
  if (!wind.empty()) {
    info.has_wind = true;
    info.wind_rotation.resize(T, 4);
    info.wind_strength.resize(T);
    for (int t = 0; t < T; ++t) {
      const int k = std::max(0, t - (kSceneRestFrames - 1));
      const WindRow* row = nullptr;
      for (const WindRow& r : wind)
        if (r.frame <= k) row = &r;
      Eigen::Vector4f q(1, 0, 0, 0);
      float strength = 0;
      if (row && row->strength > 0) {
        const Eigen::Vector3f d = (units.rotation * row->direction).normalized();
        const Eigen::Quaternionf rot = Eigen::Quaternionf::FromTwoVectors(Eigen::Vector3f::UnitZ(), d);
        q << rot.w(), rot.x(), rot.y(), rot.z();
        strength = row->strength;
      }
      info.wind_rotation.row(t) = q.transpose();
      info.wind_strength[t] = strength;
    }
  }
  // The pins are driven, like the body: rigged from it, as the data's rig drives them, they are
  // the scene's record for the step and the rollout (docs/decisions.md, "Pins rigged from the body").
  if (std::any_of(info.garments.begin(), info.garments.end(), [](const dataset::GarmentMesh& g) { return g.num_pinned() > 0; }))
    dataset::rig_pins(seq, 0);
  dataset::validate_sequence(seq, info.path);
  return scene;
}

namespace {

// The model with progress reported (the pins act inside the model's cloth constraints).
class ScenePredictor : public Predictor {
 public:
  ScenePredictor(Predictor& model, const Scene& scene, const ProgressFn& progress, ThreadChoice* threads)
      : model_(model), scene_(scene), progress_(progress), threads_(threads) {}
  std::string name() const override { return model_.name(); }
  void begin(const dataset::Sequence& seq) override { model_.begin(seq); }
  Points step(const dataset::Sequence& seq, int t, const Points& x_prev2, const Points& x_prev,
              const Points& x_now) override {
    if (threads_) omp_set_num_threads(threads_->threads_for_step(done_));
    const auto start = std::chrono::steady_clock::now();
    Points x = model_.step(seq, t, x_prev2, x_prev, x_now);
    if (threads_)
      threads_->record(done_, std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count());
    ++done_;
    if (progress_) progress_(done_, scene_.body_frames - 1);
    return x;
  }

 private:
  Predictor& model_;
  const Scene& scene_;
  const ProgressFn& progress_;
  ThreadChoice* threads_;
  int done_ = 0;
};

std::string frame_tag(int k) {
  char buf[16];
  std::snprintf(buf, sizeof buf, "%04d", k);
  return buf;
}

const std::array<uint8_t, 3> kGarmentColours[] = {{70, 130, 220}, {230, 120, 50}, {90, 180, 90}, {200, 80, 160}};

// One row of panels, body frames spread evenly from the first to the last.
void render_scene_strip(const std::string& path, const Scene& scene, int frames, int panel) {
  const dataset::Sequence& seq = scene.sequence;
  const int K = scene.body_frames;
  frames = std::clamp(frames, 1, K);
  std::vector<Points> bodies(frames);
  std::vector<std::vector<Points>> garments(frames);
  for (int i = 0; i < frames; ++i) {
    const int t = kSceneRestFrames - 1 + (frames == 1 ? K - 1 : i * (K - 1) / (frames - 1));
    bodies[i] = seq.body_at(t);
    for (int g = 0; g < seq.info.num_garments(); ++g) garments[i].push_back(seq.garment_at(g, t));
  }
  const auto meshes_of = [&](int i) {
    std::vector<Mesh> m{{&bodies[i], &seq.info.body_faces, {205, 195, 185}}};
    for (int g = 0; g < seq.info.num_garments(); ++g)
      m.push_back({&garments[i][g], &seq.info.garments[g].faces, kGarmentColours[g % 4]});
    return m;
  };
  View view;  // one view for every panel, so that the motion shows
  std::vector<Mesh> everything;
  for (int i = 0; i < frames; ++i) {
    const auto m = meshes_of(i);
    everything.insert(everything.end(), m.begin(), m.end());
  }
  view.fit(everything);
  Image strip(panel * frames, panel);
  for (int i = 0; i < frames; ++i) {
    Image im(panel, panel);
    render(im, view, meshes_of(i));
    strip.blit(im, i * panel, 0);
  }
  write_png(path, strip);
}

// Removes the temporary folder unless released.
struct TemporaryFolder {
  fs::path path;
  bool keep = false;
  ~TemporaryFolder() {
    std::error_code ec;
    if (!keep) fs::remove_all(path, ec);
  }
};

}  // namespace

std::vector<std::string> simulate_rollout_settings(const EvalConfig& model_eval, const std::vector<std::string>& user) {
  std::vector<std::string> settings;
  if (model_eval.recorded_pins)
    settings = {"eval.constraints=true", "eval.strain_limit=0", "eval.fold_limit=0", "eval.body_friction=0",
                "eval.layer_friction=0"};
  settings.insert(settings.end(), user.begin(), user.end());
  return settings;
}

Rollout simulate_scene(Predictor& model, Scene& scene, const ProgressFn& progress, bool recorded_pins,
                       ThreadChoice* threads) {
  ScenePredictor driver(model, scene, progress, threads);
  const int t0 = kSceneRestFrames - 1;
  Rollout r = rollout(driver, scene.sequence, t0, scene.body_frames - 1, recorded_pins);
  if (r.diverged_at >= 0)
    throw SimulateError("the prediction of body frame " + std::to_string(r.diverged_at + 1) +
                        " is not finite: the model left the motion it knows (check the units with --scale, the up axis "
                        "with --up, and that the garments are dressed on the first body frame)");
  dataset::Sequence& seq = scene.sequence;
  for (size_t k = 0; k < r.frames.size(); ++k) {
    const int t = r.first_frame + static_cast<int>(k);
    Eigen::Index offset = 0;
    for (int g = 0; g < seq.info.num_garments(); ++g) {
      const int n = seq.info.garments[g].num_vertices;
      seq.frames.garments[g].middleRows(static_cast<Eigen::Index>(t) * n, n) = r.frames[k].middleRows(offset, n);
      offset += n;
    }
  }
  return r;
}

void check_output_folder(const std::string& dir) {
  if (dir.empty()) throw SimulateError("--out: give the output folder");
  for (fs::path p = fs::absolute(dir); !p.empty(); p = p.parent_path()) {
    std::error_code ec;
    const fs::file_status s = fs::status(p, ec);
    if (ec && s.type() != fs::file_type::not_found)
      throw SimulateError("--out " + dir + ": " + p.string() + " cannot be examined (" + ec.message() + ")");
    if (s.type() == fs::file_type::not_found) {
      if (p == p.parent_path()) break;
      continue;
    }
    if (s.type() != fs::file_type::directory)
      throw SimulateError("--out " + dir + ": " + (p == fs::absolute(dir) ? std::string("is an existing file") : p.string() + " is a file") +
                          ", not a folder; give a folder for the outputs (it is created when missing) or move the file away");
    if (access(p.c_str(), W_OK | X_OK) != 0)
      throw SimulateError("--out " + dir + ": " + p.string() + " is not writable; give a folder you can write to");
    break;  // the nearest existing folder decides
  }
}

int write_simulation(const std::string& dir_name, const Scene& scene, const SimulateOutputs& o) {
  const fs::path dir(dir_name);
  check_output_folder(dir_name);
  fs::create_directories(dir);
  TemporaryFolder tmp{dir / (".simulate-partial-" + std::to_string(getpid()))};
  fs::remove_all(tmp.path);
  fs::create_directories(tmp.path);
  const dataset::Sequence& seq = scene.sequence;
  const int K = scene.body_frames, first = kSceneRestFrames - 1;
  int files = 0;
  std::vector<std::string> entries;  // top-level names to move into `dir`
  for (int g = 0; g < seq.info.num_garments(); ++g) {
    const dataset::GarmentMesh& mesh = seq.info.garments[g];
    fs::create_directories(tmp.path / mesh.name);
    entries.push_back(mesh.name);
    dataset::PointCache cache;
    for (int k = 0; k < K; ++k) {
      const Points x = scene.to_input_units(seq.garment_at(g, first + k));
      const Points normals = dataset::vertex_normals(x, mesh.faces);
      dataset::write_obj((tmp.path / mesh.name / (mesh.name + "_" + frame_tag(k) + ".obj")).string(), x, mesh.faces,
                         &mesh.uv, &normals);
      cache.frames.push_back(x);
      ++files;
    }
    dataset::write_pc2((tmp.path / (mesh.name + ".pc2")).string(), cache);
    entries.push_back(mesh.name + ".pc2");
    ++files;
  }
  dataset::PointCache body;
  for (int k = 0; k < K; ++k) body.frames.push_back(scene.to_input_units(seq.body_at(first + k)));
  dataset::write_obj((tmp.path / "body.obj").string(), body.frames.front(), seq.info.body_faces);
  dataset::write_pc2((tmp.path / "body.pc2").string(), body);
  entries.insert(entries.end(), {"body.obj", "body.pc2"});
  files += 2;
  dataset::Sequence stored = seq;
  stored.info.path = o.sequence_id + ".h5";
  dataset::write_sequence((tmp.path / (o.sequence_id + ".h5")).string(), stored);
  dataset::DatasetManifest manifest;
  manifest.root = tmp.path.string();
  manifest.source = "layersnet simulate: a predicted scene without ground truth (its garments are the prediction)";
  manifest.test = {o.sequence_id};
  dataset::write_manifest(manifest);
  entries.insert(entries.end(), {o.sequence_id + ".h5", "dataset.json"});
  files += 2;
  if (o.strip_frames > 0) {
    render_scene_strip((tmp.path / "strip.png").string(), scene, o.strip_frames, o.panel_size);
    entries.push_back("strip.png");
    ++files;
  }
  for (const std::string& e : entries) {  // everything is complete: move it into place
    fs::remove_all(dir / e);
    fs::rename(tmp.path / e, dir / e);
  }
  return files;
}

}  // namespace layersnet::eval
