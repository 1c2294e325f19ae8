// Mesh export and strip rendering (see export.h).
#include "eval/export.h"

#include "eval/render.h"

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <stdexcept>

namespace layersnet::eval {

void write_obj(const std::string& path, const Eigen::Ref<const Points>& x, const dataset::Faces& faces) {
  std::FILE* f = std::fopen(path.c_str(), "w");
  if (!f) throw std::runtime_error(path + ": cannot be written (check the --out folder)");
  for (Eigen::Index v = 0; v < x.rows(); ++v) std::fprintf(f, "v %.6g %.6g %.6g\n", x(v, 0), x(v, 1), x(v, 2));
  for (Eigen::Index i = 0; i < faces.rows(); ++i)
    std::fprintf(f, "f %d %d %d\n", faces(i, 0) + 1, faces(i, 1) + 1, faces(i, 2) + 1);
  if (std::fclose(f) != 0) throw std::runtime_error(path + ": write failed (disk full?)");
}

void write_ply(const std::string& path, const Eigen::Ref<const Points>& x, const dataset::Faces& faces) {
  std::ofstream f(path, std::ios::binary);
  f << "ply\nformat binary_little_endian 1.0\nelement vertex " << x.rows()
    << "\nproperty float x\nproperty float y\nproperty float z\nelement face " << faces.rows()
    << "\nproperty list uchar int vertex_indices\nend_header\n";
  for (Eigen::Index v = 0; v < x.rows(); ++v)
    for (int c = 0; c < 3; ++c) {
      const float value = x(v, c);
      f.write(reinterpret_cast<const char*>(&value), sizeof value);
    }
  for (Eigen::Index i = 0; i < faces.rows(); ++i) {
    const uint8_t three = 3;
    f.write(reinterpret_cast<const char*>(&three), 1);
    for (int c = 0; c < 3; ++c) {
      const int32_t id = faces(i, c);
      f.write(reinterpret_cast<const char*>(&id), sizeof id);
    }
  }
  if (!f) throw std::runtime_error(path + ": cannot be written (check the --out folder)");
}

namespace {
const std::array<uint8_t, 3> kGarmentColours[] = {{70, 130, 220}, {230, 120, 50}, {90, 180, 90}, {200, 80, 160}};

std::string frame_tag(int t) {
  char buf[16];
  std::snprintf(buf, sizeof buf, "%04d", t);
  return buf;
}
}  // namespace

int export_rollout(const std::string& dir_name, const dataset::Sequence& seq, const Rollout& r,
                   const ExportOptions& o) {
  if (o.format != "obj" && o.format != "ply")
    throw std::invalid_argument("export format '" + o.format + "' is not supported: use obj or ply");
  const std::filesystem::path dir(dir_name);
  std::filesystem::create_directories(dir);
  const auto write = [&](const std::string& stem, const Eigen::Ref<const Points>& x, const dataset::Faces& f) {
    const std::string p = (dir / (stem + "." + o.format)).string();
    if (o.format == "obj")
      write_obj(p, x, f);
    else
      write_ply(p, x, f);
  };
  int files = 0;
  for (size_t k = 0; k < r.frames.size(); ++k) {
    const int t = r.first_frame + static_cast<int>(k);
    const std::string tag = frame_tag(t);
    write("body_" + tag, seq.body_at(t), seq.info.body_faces);
    ++files;
    Eigen::Index offset = 0;
    for (int g = 0; g < seq.info.num_garments(); ++g) {
      const auto& mesh = seq.info.garments[g];
      write("pred_" + mesh.name + "_" + tag, r.frames[k].middleRows(offset, mesh.num_vertices), mesh.faces);
      write("gt_" + mesh.name + "_" + tag, seq.garment_at(g, t), mesh.faces);
      files += 2;
      offset += mesh.num_vertices;
    }
  }
  if (o.strip_frames > 0) render_strip((dir / "strip.png").string(), seq, r, o.strip_frames, o.panel_size);
  return files;
}

void render_strip(const std::string& path, const dataset::Sequence& seq, const Rollout& r, int frames, int panel) {
  const int n = static_cast<int>(r.frames.size());
  frames = std::max(1, std::min(frames, n));
  std::vector<int> chosen;  // rollout indices, evenly spread, last frame included
  for (int i = 0; i < frames; ++i) chosen.push_back(frames == 1 ? n - 1 : i * (n - 1) / (frames - 1));
  // Per panel: the body and each garment (predicted or ground truth) of one frame.
  std::vector<std::vector<Points>> garments(2 * frames);
  std::vector<Points> bodies(frames);
  for (int i = 0; i < frames; ++i) {
    const int t = r.first_frame + chosen[i];
    bodies[i] = seq.body_at(t);
    Eigen::Index offset = 0;
    for (int g = 0; g < seq.info.num_garments(); ++g) {
      const int nv = seq.info.garments[g].num_vertices;
      garments[i].push_back(r.frames[chosen[i]].middleRows(offset, nv));
      garments[frames + i].push_back(seq.garment_at(g, t));
      offset += nv;
    }
  }
  const auto meshes_of = [&](int panel_index, int frame_index) {
    std::vector<Mesh> m;
    m.push_back({&bodies[frame_index], &seq.info.body_faces, {205, 195, 185}});
    for (int g = 0; g < seq.info.num_garments(); ++g)
      m.push_back({&garments[panel_index][g], &seq.info.garments[g].faces, kGarmentColours[g % 4]});
    return m;
  };
  // One view for every panel, so that motion across frames is visible.
  View view;
  view.up_axis = seq.info.up_axis;
  std::vector<Mesh> everything;
  for (int i = 0; i < frames; ++i)
    for (int row = 0; row < 2; ++row) {
      const auto m = meshes_of(row * frames + i, i);
      everything.insert(everything.end(), m.begin(), m.end());
    }
  view.fit(everything);
  Image strip(panel * frames, panel * 2);
  for (int row = 0; row < 2; ++row)
    for (int i = 0; i < frames; ++i) {
      Image im(panel, panel);
      render(im, view, meshes_of(row * frames + i, i));
      strip.blit(im, i * panel, row * panel);
    }
  write_png(path, strip);
}

}  // namespace layersnet::eval
