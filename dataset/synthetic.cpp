// Synthetic scenes (see synthetic.h). Geometry is generated, not simulated: the tubes follow
// the body with a small lag and ripple, which is all tests and benchmarks need.
#include "dataset/synthetic.h"

#include <cmath>
#include <cstdio>
#include <filesystem>

namespace layersnet::dataset {
namespace {

constexpr float kPi = 3.14159265358979f;

// Deterministic [0, 1) numbers from a seed (splitmix64).
float unit_random(uint64_t& state) {
  uint64_t z = (state += 0x9e3779b97f4a7c15ull);
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
  z ^= z >> 31;
  return static_cast<float>(z >> 40) / static_cast<float>(1ull << 24);
}

Eigen::Vector3f root_at(const SyntheticOptions& o, float t) {
  return Eigen::Vector3f(o.motion * std::sin(0.4f * t), 0.5f * o.motion * std::sin(0.25f * t), 0.f) +
         Eigen::Vector3f(o.offset[0], o.offset[1], o.offset[2]);
}

GarmentAttributes random_attributes(uint64_t& rng) {
  GarmentAttributes a;
  a.tension_stiffness = 15 + 85 * unit_random(rng);
  a.bending_stiffness = 15 + 185 * unit_random(rng);
  a.mass = 0.2f + 0.6f * unit_random(rng);
  a.self_friction = 40 + 40 * unit_random(rng);
  return a;
}

// Cylinder, outward counter-clockwise faces (side, then bottom and top caps if any).
void make_body(const SyntheticOptions& o, Points& rest, Faces& faces) {
  const int R = std::max(o.body_rings, 2), S = std::max(o.body_segments, 3);
  rest.resize(R * S + (o.body_caps ? 2 : 0), 3);
  for (int r = 0; r < R; ++r)
    for (int s = 0; s < S; ++s) {
      const float a = 2 * kPi * s / S;
      rest.row(r * S + s) << o.body_radius * std::cos(a), o.body_radius * std::sin(a),
          o.height * r / (R - 1) + o.body_bottom;
    }
  std::vector<int32_t> f;
  auto tri = [&](int a, int b, int c) { f.insert(f.end(), {a, b, c}); };
  for (int r = 0; r + 1 < R; ++r)
    for (int s = 0; s < S; ++s) {
      const int s1 = (s + 1) % S;
      tri(r * S + s, r * S + s1, (r + 1) * S + s);
      tri(r * S + s1, (r + 1) * S + s1, (r + 1) * S + s);
    }
  if (o.body_caps) {
    const int c0 = R * S, c1 = R * S + 1;
    rest.row(c0) << 0, 0, o.body_bottom;
    rest.row(c1) << 0, 0, o.height + o.body_bottom;
    for (int s = 0; s < S; ++s) {
      const int s1 = (s + 1) % S;
      tri(c0, s1, s);
      tri(c1, (R - 1) * S + s, (R - 1) * S + s1);
    }
  }
  faces = Eigen::Map<Faces>(f.data(), static_cast<Eigen::Index>(f.size() / 3), 3);
}

// A garment from its rest shape (V, 3) and flat triangle lists: 3 vertex ids and 3 UV corners
// (u, v) per face, a panel per face; random attributes drawn from `rng`.
GarmentMesh assemble_garment(const std::string& name, const std::string& type, const Points& rest,
                             std::vector<int32_t>& f, std::vector<float>& uv, std::vector<int32_t> panel,
                             uint64_t& rng) {
  GarmentMesh g;
  g.name = name;
  g.type = type;
  g.num_vertices = static_cast<int>(rest.rows());
  g.faces = Eigen::Map<Faces>(f.data(), static_cast<Eigen::Index>(f.size() / 3), 3);
  g.uv = Eigen::Map<Uvs>(uv.data(), static_cast<Eigen::Index>(uv.size() / 2), 2);
  g.panel = std::move(panel);
  g.rest = rest;
  g.attributes = random_attributes(rng);
  return g;
}

// Open tube of `rings` x `segments` vertices; two UV panels split at angle 0 and pi.
GarmentMesh make_tube(const SyntheticOptions& o, float radius, const std::string& name,
                      const std::string& type, uint64_t& rng, Points& rest) {
  const int R = std::max(o.rings, 2), S = std::max(o.segments / 2 * 2, 4);
  rest.resize(R * S, 3);
  for (int r = 0; r < R; ++r)
    for (int s = 0; s < S; ++s) {
      const float a = 2 * kPi * s / S;
      rest.row(r * S + s) << radius * std::cos(a), radius * std::sin(a), o.height * r / (R - 1) * 0.8f;
    }
  std::vector<int32_t> f, panel;
  std::vector<float> uv;
  const float arc = 2 * kPi * radius / S;  // scene units between neighbouring columns
  auto corner = [&](int r, int s_unwrapped, int p) {
    const int s_local = s_unwrapped - p * (S / 2);  // column inside the panel, 0..S/2
    uv.push_back(o.uv_per_unit * arc * s_local + 0.5f * p);  // panels side by side in UV
    uv.push_back(o.uv_per_unit * o.height * 0.8f * r / (R - 1));
  };
  for (int r = 0; r + 1 < R; ++r)
    for (int s = 0; s < S; ++s) {
      const int s1 = (s + 1) % S, p = s < S / 2 ? 0 : 1;
      f.insert(f.end(), {r * S + s, r * S + s1, (r + 1) * S + s});
      corner(r, s, p), corner(r, s + 1, p), corner(r + 1, s, p);
      f.insert(f.end(), {r * S + s1, (r + 1) * S + s1, (r + 1) * S + s});
      corner(r, s + 1, p), corner(r + 1, s + 1, p), corner(r + 1, s, p);
      panel.push_back(p);
      panel.push_back(p);
    }
  return assemble_garment(name, type, rest, f, uv, std::move(panel), rng);
}

// Open cylindrical sheet (SyntheticSheet): vertex (i, j) is row i * along + j; one UV panel.
GarmentMesh make_sheet(const SyntheticOptions& o, const SyntheticSheet& sheet, const std::string& name,
                       const std::string& type, uint64_t& rng, Points& rest) {
  const int U = std::max(sheet.around, 2), V = std::max(sheet.along, 2);
  rest.resize(U * V, 3);
  for (int i = 0; i < U; ++i)
    for (int j = 0; j < V; ++j) {
      const float a = i * o.sheet_spacing / sheet.radius;
      rest.row(i * V + j) << sheet.radius * std::cos(a), sheet.radius * std::sin(a), sheet.z0 + j * o.sheet_spacing;
    }
  std::vector<int32_t> f;
  std::vector<float> uv;
  auto corner = [&](int i, int j) { uv.push_back(sheet.uv_step[0] * i), uv.push_back(sheet.uv_step[1] * j); };
  for (int i = 0; i + 1 < U; ++i)
    for (int j = 0; j + 1 < V; ++j) {
      const int a = i * V + j, b = (i + 1) * V + j, c = (i + 1) * V + j + 1, d = i * V + j + 1;
      f.insert(f.end(), {a, b, c, a, c, d});
      corner(i, j), corner(i + 1, j), corner(i + 1, j + 1);
      corner(i, j), corner(i + 1, j + 1), corner(i, j + 1);
    }
  const std::size_t faces = f.size() / 3;
  return assemble_garment(name, type, rest, f, uv, std::vector<int32_t>(faces, 0), rng);
}

}  // namespace

Sequence make_synthetic_sequence(const SyntheticOptions& o) {
  uint64_t rng = o.seed * 7919 + 17;
  Sequence seq;
  SequenceInfo& s = seq.info;
  const int T = std::max(o.frames, 3);
  s.path = "synthetic";
  s.num_frames = T;
  s.body_friction = 40 + 40 * unit_random(rng);
  Points body_rest;
  make_body(o, body_rest, s.body_faces);
  s.num_body_vertices = static_cast<int>(body_rest.rows());
  s.translation.resize(T, 3);
  seq.frames.first = 0;
  seq.frames.count = T;
  seq.frames.body.resize(static_cast<Eigen::Index>(T) * s.num_body_vertices, 3);
  const Eigen::RowVector3f body_offset(o.body_offset[0], o.body_offset[1], o.body_offset[2]);
  for (int t = 0; t < T; ++t) {
    const Eigen::RowVector3f root = root_at(o, static_cast<float>(t)).transpose();
    s.translation.row(t) = root;
    seq.frames.body.middleRows(static_cast<Eigen::Index>(t) * s.num_body_vertices, s.num_body_vertices) =
        (body_rest.rowwise() + root).rowwise() + body_offset;
  }
  static const char* kTypes[] = {"tee", "jacket", "dress_sleeveless"};
  const float phase = 6.f * unit_random(rng);
  const int G = o.sheets.empty() ? std::clamp(o.garments, 1, 3) : static_cast<int>(o.sheets.size());
  for (int gi = 0; gi < G; ++gi) {
    Points rest;
    const char* type = kTypes[gi % 3];
    const std::string name = std::string("g") + std::to_string(gi) + "_" + type;
    s.garments.push_back(o.sheets.empty() ? make_tube(o, o.radius + gi * o.layer_gap, name, type, rng, rest)
                                          : make_sheet(o, o.sheets[gi], name, type, rng, rest));
    Points pos(static_cast<Eigen::Index>(T) * rest.rows(), 3);
    for (int t = 0; t < T; ++t) {
      const Eigen::RowVector3f lagged = root_at(o, t - 0.7f).transpose();
      for (Eigen::Index v = 0; v < rest.rows(); ++v) {
        const float ripple = 0.03f * std::sin(1.3f * t + 2.f * rest(v, 2) + phase + gi);
        if (o.sheets.empty()) {
          pos.row(t * rest.rows() + v) = rest.row(v) * (1.f + ripple) + lagged;
        } else {  // about the sheet's mid-height: tall sheets keep their layers' heights
          const Eigen::RowVector3f mid(0.f, 0.f, o.sheets[gi].z0 + 0.5f * (o.sheets[gi].along - 1) * o.sheet_spacing);
          pos.row(t * rest.rows() + v) = (rest.row(v) - mid) * (1.f + ripple) + mid + lagged;
        }
      }
    }
    seq.frames.garments.push_back(std::move(pos));
  }
  if (o.wind) {
    s.has_wind = true;
    s.wind_rotation.resize(T, 4);
    s.wind_strength.resize(T);
    for (int t = 0; t < T; ++t) {
      const int segment = 3 * t / T;  // 0: calm, 1 and 2: two directions
      const float half = segment == 2 ? 0.6f : 0.3f;
      s.wind_rotation.row(t) << std::cos(half), std::sin(half), 0.f, 0.f;  // about x
      s.wind_strength(t) = segment == 0 ? 0.f : segment == 1 ? 150.f : 300.f;
    }
  }
  return seq;
}

DatasetManifest write_synthetic_dataset(const std::string& root, int n_train, int n_val, int n_test,
                                        const SyntheticOptions& options,
                                        const SequenceWriteOptions& write_options) {
  DatasetManifest m;
  m.root = root;
  const int garments = options.sheets.empty() ? options.garments : static_cast<int>(options.sheets.size());
  m.source = "layersnet synthetic scene (dataset/synthetic.cpp), " + std::to_string(garments) +
             " garment(s), " + std::to_string(options.frames) + " frames";
  const int total = n_train + n_val + n_test;
  std::vector<std::string> ids;
  for (int i = 0; i < total; ++i) {
    char id[16];
    std::snprintf(id, sizeof id, "s%04d", i);
    ids.push_back(id);
    (i < n_train ? m.train : i < n_train + n_val ? m.val : m.test).push_back(id);
  }
  std::filesystem::create_directories(root);
  write_manifest(m);
  for (int i = 0; i < total; ++i) {
    SyntheticOptions o = options;
    o.seed = options.seed + static_cast<uint64_t>(i);
    o.wind = options.wind && i % 2 == 0;
    write_sequence(m.sequence_path(ids[i]), make_synthetic_sequence(o), write_options);
  }
  return m;
}

}  // namespace layersnet::dataset
