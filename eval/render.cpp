// Software renderer and PNG writer (see render.h).
#include "eval/render.h"

#include "dataset/file_io.h"

#include <zlib.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <limits>
#include <stdexcept>

namespace layersnet::eval {

Image::Image(int w, int h)
    : width(w),
      height(h),
      rgb(static_cast<size_t>(w) * h * 3, 255),
      depth(static_cast<size_t>(w) * h, std::numeric_limits<float>::infinity()) {}

void Image::blit(const Image& src, int x0, int y0) {
  for (int y = 0; y < src.height; ++y)
    for (int x = 0; x < src.width; ++x) {
      const int tx = x0 + x, ty = y0 + y;
      if (tx < 0 || ty < 0 || tx >= width || ty >= height) continue;
      for (int c = 0; c < 3; ++c)
        rgb[(static_cast<size_t>(ty) * width + tx) * 3 + c] = src.rgb[(static_cast<size_t>(y) * src.width + x) * 3 + c];
    }
}

namespace {
void put_u32(std::vector<uint8_t>& out, uint32_t v) {
  for (int s = 24; s >= 0; s -= 8) out.push_back(static_cast<uint8_t>(v >> s));
}
void chunk(std::vector<uint8_t>& out, const char* type, const std::vector<uint8_t>& data) {
  put_u32(out, static_cast<uint32_t>(data.size()));
  const size_t start = out.size();
  out.insert(out.end(), type, type + 4);
  out.insert(out.end(), data.begin(), data.end());
  put_u32(out, static_cast<uint32_t>(crc32(0L, out.data() + start, static_cast<uInt>(out.size() - start))));
}
}  // namespace

void write_png(const std::string& path, const Image& im) {
  std::vector<uint8_t> raw;  // each row: filter byte 0 + RGB
  raw.reserve(static_cast<size_t>(im.height) * (im.width * 3 + 1));
  for (int y = 0; y < im.height; ++y) {
    raw.push_back(0);
    const auto row = im.rgb.begin() + static_cast<std::ptrdiff_t>(y) * im.width * 3;
    raw.insert(raw.end(), row, row + im.width * 3);
  }
  uLongf packed_size = compressBound(static_cast<uLong>(raw.size()));
  std::vector<uint8_t> packed(packed_size);
  if (compress2(packed.data(), &packed_size, raw.data(), static_cast<uLong>(raw.size()), 6) != Z_OK)
    throw std::runtime_error(path + ": zlib failed to compress the image");
  packed.resize(packed_size);
  std::vector<uint8_t> out = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
  std::vector<uint8_t> ihdr;
  put_u32(ihdr, static_cast<uint32_t>(im.width));
  put_u32(ihdr, static_cast<uint32_t>(im.height));
  ihdr.insert(ihdr.end(), {8, 2, 0, 0, 0});  // 8-bit, RGB, deflate, no filter, no interlace
  chunk(out, "IHDR", ihdr);
  chunk(out, "IDAT", packed);
  chunk(out, "IEND", {});
  io::write_file_atomic(path, std::string_view(reinterpret_cast<const char*>(out.data()), out.size()));
}

namespace {
// Screen plane (right, up) and depth of a world point for the view's up axis.
Eigen::Vector3f screen_coords(const Eigen::Vector3f& p, char up) {
  return up == 'y' ? Eigen::Vector3f(p.x(), p.y(), -p.z()) : Eigen::Vector3f(p.x(), p.z(), p.y());
}
}  // namespace

void View::fit(const std::vector<Mesh>& meshes) {
  Eigen::Vector2f a = Eigen::Vector2f::Constant(std::numeric_limits<float>::infinity()), b = -a;
  for (const auto& m : meshes)
    for (Eigen::Index v = 0; v < m.x->rows(); ++v) {
      const Eigen::Vector3f s = screen_coords(m.x->row(v).transpose(), up_axis);
      a = a.cwiseMin(s.head<2>());
      b = b.cwiseMax(s.head<2>());
    }
  if (!std::isfinite(a.x())) a = Eigen::Vector2f::Zero(), b = Eigen::Vector2f::Ones();
  const Eigen::Vector2f margin = 0.05f * (b - a).cwiseMax(1e-3f);
  lo = a - margin;
  hi = b + margin;
}

Eigen::Vector3f View::project(const Eigen::Vector3f& p, int w, int h) const {
  const Eigen::Vector3f s = screen_coords(p, up_axis);
  // One scale for both axes (no distortion), centred.
  const float scale = std::min(w / (hi.x() - lo.x()), h / (hi.y() - lo.y()));
  const Eigen::Vector2f c = 0.5f * (lo + hi);
  return {w * 0.5f + (s.x() - c.x()) * scale, h * 0.5f - (s.y() - c.y()) * scale, s.z()};
}

void render(Image& im, const View& view, const std::vector<Mesh>& meshes) {
  const Eigen::Vector3f view_dir = view.up_axis == 'y' ? Eigen::Vector3f(0, 0, -1) : Eigen::Vector3f(0, 1, 0);
  for (const auto& m : meshes) {
    const auto& F = *m.faces;
    for (Eigen::Index f = 0; f < F.rows(); ++f) {
      const Eigen::Vector3f a = m.x->row(F(f, 0)).transpose(), b = m.x->row(F(f, 1)).transpose(),
                            c = m.x->row(F(f, 2)).transpose();
      const Eigen::Vector3f n = (b - a).cross(c - a);
      const float len = n.norm();
      if (!(len > 0)) continue;
      const float shade = 0.25f + 0.75f * std::abs(n.dot(view_dir)) / len;
      const Eigen::Vector3f p0 = view.project(a, im.width, im.height), p1 = view.project(b, im.width, im.height),
                            p2 = view.project(c, im.width, im.height);
      const float area = (p1.x() - p0.x()) * (p2.y() - p0.y()) - (p2.x() - p0.x()) * (p1.y() - p0.y());
      if (std::abs(area) < 1e-12f) continue;
      const int x0 = std::max(0, static_cast<int>(std::floor(std::min({p0.x(), p1.x(), p2.x()}))));
      const int x1 = std::min(im.width - 1, static_cast<int>(std::ceil(std::max({p0.x(), p1.x(), p2.x()}))));
      const int y0 = std::max(0, static_cast<int>(std::floor(std::min({p0.y(), p1.y(), p2.y()}))));
      const int y1 = std::min(im.height - 1, static_cast<int>(std::ceil(std::max({p0.y(), p1.y(), p2.y()}))));
      for (int y = y0; y <= y1; ++y)
        for (int x = x0; x <= x1; ++x) {
          const float px = x + 0.5f, py = y + 0.5f;
          // Barycentric weights (either winding).
          const float w0 = ((p1.x() - px) * (p2.y() - py) - (p2.x() - px) * (p1.y() - py)) / area;
          const float w1 = ((p2.x() - px) * (p0.y() - py) - (p0.x() - px) * (p2.y() - py)) / area;
          const float w2 = 1.f - w0 - w1;
          if (w0 < 0 || w1 < 0 || w2 < 0) continue;
          const float z = w0 * p0.z() + w1 * p1.z() + w2 * p2.z();
          const size_t i = static_cast<size_t>(y) * im.width + x;
          if (z >= im.depth[i]) continue;
          im.depth[i] = z;
          for (int k = 0; k < 3; ++k) im.rgb[i * 3 + k] = static_cast<uint8_t>(std::min(255.f, m.colour[k] * shade));
        }
    }
  }
}

}  // namespace layersnet::eval
