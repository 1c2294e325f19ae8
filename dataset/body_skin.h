#pragma once
// Garment points carried by the body surface: each point bound to its nearest body vertex and
// that vertex's mesh neighbours (weights ∝ 1 / squared distance), with its offset from each kept
// in the body vertex's local frame (tangent, bitangent, normal). Carrying the binding to another
// body pose gives x' = Σ w_i (h'_i + F'_i d_i): the points move with the surface's translation
// and rotation, and a rigidly moved body carries them exactly.
//
// One road for two jobs: the skinning baseline (eval/rollout.h) binds once and carries to every
// later frame; the model's body-carried velocity base (ModelConfig::velocity_base = "body")
// binds x_t to the body at t and carries it one frame, to t+1.
#include "dataset/patches.h"
#include "dataset/sequence.h"

#include <Eigen/Core>

#include <cstdint>
#include <vector>

namespace layersnet::dataset {

// What the body mesh's faces say about its vertices: mesh neighbours (ascending) and the
// neighbour each local frame's tangent points to (the lowest-numbered one; itself when none).
struct BodyTopology {
  std::vector<std::vector<int32_t>> neighbours;  // (B,)
  std::vector<int32_t> tangent_neighbour;        // (B,)
};
BodyTopology body_topology(const Faces& faces, int num_body_vertices);

// Body-local frames: per body vertex the columns (tangent, bitangent, normal) of a rotation,
// stored column-major in the row (so Map<Matrix3f>(row) is the frame). body (B, 3) -> (B, 9).
using BodyFrames = Eigen::Matrix<float, Eigen::Dynamic, 9, Eigen::RowMajor>;
BodyFrames body_frames(const Eigen::Ref<const Points>& body, const Faces& faces, const BodyTopology& topology);

struct SkinBinding {
  struct Carrier {
    int32_t body_vertex = 0;
    float weight = 0;        // the carriers of one point sum to 1
    Eigen::Vector3f offset;  // in the body vertex's frame, or world axes when not rotating
  };
  std::vector<int32_t> offsets;   // (Q + 1): point q's carriers are carriers[offsets[q], offsets[q + 1])
  std::vector<Carrier> carriers;  // every point's, point after point
  bool rotate = true;
  int64_t points() const { return offsets.empty() ? 0 : static_cast<int64_t>(offsets.size()) - 1; }
};

// Binds points x (Q, 3) to the body (B, 3) whose frames are `frames` (ignored when !rotate).
SkinBinding bind_to_body(const Eigen::Ref<const Points>& x, const Eigen::Ref<const Points>& body,
                         const BodyFrames& frames, const BodyTopology& topology, bool rotate = true);

// Where the bound points are on the body `body` (B, 3) with frames `frames`: (Q, 3).
Points carry_with_body(const SkinBinding& binding, const Eigen::Ref<const Points>& body, const BodyFrames& frames);

// Averages a per-vertex field over the garment mesh: `iterations` Jacobi steps of
// u_v <- (u_v + mean of u over v's mesh neighbours) / 2. A field that is the same on every vertex
// of a connected garment stays as it is. u (N, 3); neighbours: N rows (SequenceStructure).
void smooth_over_mesh(Points& u, const Csr& neighbours, int iterations);

}  // namespace layersnet::dataset
