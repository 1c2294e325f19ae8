#pragma once
// The index of every op on the tape: one X-macro entry per op, X(EnumName, function_stem).
// The enum, the backward dispatch and the gradient-check coverage test are all generated
// from these lists, so an op cannot exist without a backward and a check.
#include "autodiff/op_list_dense.h"
#include "autodiff/op_list_graph.h"

#define LAYERSNET_ALL_OPS(X) \
  LAYERSNET_DENSE_OPS(X)     \
  LAYERSNET_GRAPH_OPS(X)
