#pragma once
// Graph, geometry and solver ops (autodiff/ops_graph.h, ops_geometry.h, ops_attention.h, ops_solve.h, ops_cloth.h):
// X(EnumName, function_stem). Add a line per new op.
#define LAYERSNET_GRAPH_OPS(X)      \
  X(GatherRows, gather_rows)        \
  X(ScatterAddRows, scatter_add_rows) \
  X(SegmentSum, segment_sum)        \
  X(SegmentSoftmax, segment_softmax) \
  X(ConcatRows, concat_rows)         \
  X(RowNorm, row_norm)              \
  X(RowNormalize, row_normalize)    \
  X(Cross3, cross3)                 \
  X(Rotate3, rotate3)               \
  X(RotMapApply, rot_map_apply)     \
  X(RotInvAttention, rot_inv_attention) \
  X(BlockSpdSolve, block_spd_solve)  \
  X(VertexNormals, vertex_normals)   \
  X(SpringEnergy, spring_energy)     \
  X(DihedralAlignment, dihedral_alignment)
