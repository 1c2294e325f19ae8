#pragma once
// Dense ops (autodiff/ops_dense.h): X(EnumName, function_stem). Add a line per new op.
#define LAYERSNET_DENSE_OPS(X) \
  X(Add, add)
