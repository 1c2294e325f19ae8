#pragma once
// A small software renderer for quick looks at rollouts: orthographic view,
// z-buffered flat-shaded triangles, PNG output (8-bit RGB, zlib).
//
// View: looking along +y (front of a z-up scene: x to the right, z up), or along −z for a
// y-up scene (x right, y up). Shading: |n·view| (two-sided, cloth has no inside), times
// the mesh colour, over a white background.
#include "dataset/sequence.h"

#include <Eigen/Core>

#include <array>
#include <cstdint>
#include <string>
#include <vector>

namespace layersnet::eval {

struct Image {
  int width = 0, height = 0;
  std::vector<uint8_t> rgb;  // (height, width, 3), row-major, top row first
  std::vector<float> depth;  // (height, width): smaller = nearer
  Image(int w, int h);
  void blit(const Image& src, int x0, int y0);  // copies src into this at (x0, y0)
};

// Writes an 8-bit RGB PNG. Throws naming the path when it cannot be written.
void write_png(const std::string& path, const Image& image);

struct Mesh {
  const dataset::Points* x = nullptr;  // (V, 3) world
  const dataset::Faces* faces = nullptr;
  std::array<uint8_t, 3> colour{200, 200, 200};
};

// Screen mapping shared by the panels of a strip: a world box fitted into w×h pixels.
struct View {
  char up_axis = 'z';
  Eigen::Vector2f lo{0, 0}, hi{1, 1};  // screen-plane box (right, up), world units
  // Fits the box around every vertex of the meshes (5 % margin).
  void fit(const std::vector<Mesh>& meshes);
  Eigen::Vector3f project(const Eigen::Vector3f& p, int w, int h) const;  // (px, py, depth)
};

// Draws the meshes into `image` (keeps what is already drawn nearer).
void render(Image& image, const View& view, const std::vector<Mesh>& meshes);

}  // namespace layersnet::eval
