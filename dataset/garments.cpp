#include "dataset/garments.h"

#include <algorithm>
#include <cmath>
#include <set>
#include <stdexcept>

namespace layersnet::dataset {

GarmentLayout garment_layout(const SequenceInfo& info) {
  GarmentLayout L;
  L.offsets.push_back(0);
  for (const auto& g : info.garments) {
    L.offsets.push_back(L.offsets.back() + g.num_vertices);
    L.faces.push_back(g.faces);
    L.types.push_back(g.type);
  }
  return L;
}

Faces inner_faces(const GarmentLayout& L) {
  Eigen::Index rows = 0;
  for (int g = 0; g + 1 < L.num_garments(); ++g) rows += L.faces[g].rows();
  Faces out(rows, 3);
  Eigen::Index r = 0;
  for (int g = 0; g + 1 < L.num_garments(); ++g) {
    out.middleRows(r, L.faces[g].rows()) = L.faces[g].array() + L.offsets[g];
    r += L.faces[g].rows();
  }
  return out;
}

Points garments_at(const SequenceInfo& info, const FrameWindow& frames, int t) {
  Points x(info.total_garment_vertices(), 3);
  Eigen::Index row = 0;
  for (int g = 0; g < info.num_garments(); ++g) {
    const int n = info.garments[static_cast<std::size_t>(g)].num_vertices;
    x.middleRows(row, n) = frames.garment_at(g, t, n);
    row += n;
  }
  return x;
}

Points rest_shapes(const SequenceInfo& info, const Points& first_frame) {
  if (first_frame.rows() != info.total_garment_vertices())
    throw std::invalid_argument("rest_shapes: " + std::to_string(first_frame.rows()) + " rows for " +
                                std::to_string(info.total_garment_vertices()) + " garment vertices");
  Points x = first_frame;
  Eigen::Index row = 0;
  for (const auto& mesh : info.garments) {
    if (mesh.rest.rows() == mesh.num_vertices) x.middleRows(row, mesh.num_vertices) = mesh.rest;
    row += mesh.num_vertices;
  }
  return x;
}

GarmentEdges garment_edges(const SequenceInfo& info, const Points& rest) {
  GarmentEdges out;
  Eigen::Index offset = 0;
  for (const GarmentMesh& mesh : info.garments) {
    std::set<std::pair<int, int>> seen;
    for (int f = 0; f < mesh.num_faces(); ++f)
      for (int c = 0; c < 3; ++c) {
        const int a = mesh.faces(f, c), b = mesh.faces(f, (c + 1) % 3);
        if (!seen.insert({std::min(a, b), std::max(a, b)}).second) continue;
        out.rows.push_back({offset + a, offset + b});
        out.rest.push_back((rest.row(offset + a) - rest.row(offset + b)).cast<double>().norm());
      }
    offset += mesh.num_vertices;
  }
  return out;
}

std::vector<double> edge_strains(const GarmentEdges& edges, const Points& x) {
  std::vector<double> out;
  out.reserve(edges.rows.size());
  for (size_t e = 0; e < edges.rows.size(); ++e)
    if (edges.rest[e] > 0) {
      const auto [a, b] = edges.rows[e];
      out.push_back(std::abs((x.row(a) - x.row(b)).cast<double>().norm() / edges.rest[e] - 1.0));
    }
  return out;
}

}  // namespace layersnet::dataset
