#pragma once
// Edge kinds and head masks for the attention tests, shaped like LayersNet's: world heads
// attend world and inter edges, mesh heads mesh edges, and world and mesh edges send the
// (s + r) message. Heads alternate (world, mesh, world, ...) so that a two-head test has one
// of each.
#include <cstdint>
#include <vector>

namespace layersnet::ad::testing {

enum EdgeKind : int32_t { kWorldEdge = 0, kMeshEdge = 1, kInterEdge = 2 };
constexpr uint32_t kSelfMessageKinds = (1u << kWorldEdge) | (1u << kMeshEdge);

inline std::vector<uint32_t> alternating_head_kinds(int64_t heads) {
  std::vector<uint32_t> table;
  for (int64_t h = 0; h < heads; ++h)
    table.push_back(h % 2 == 0 ? (1u << kWorldEdge) | (1u << kInterEdge) : (1u << kMeshEdge));
  return table;
}

}  // namespace layersnet::ad::testing
