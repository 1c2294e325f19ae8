#pragma once
// Dense ops (autodiff/ops_dense.h): X(EnumName, function_stem). Add a line per new op.
// Means share their sum's op (ReduceParams::factor is 1 or 1/count).
#define LAYERSNET_DENSE_OPS(X) \
  X(Linear, linear)            \
  X(LinearRelu, linear_relu)   \
  X(Mlp, mlp)                  \
  X(Add, add)                  \
  X(Sub, sub)                  \
  X(Mul, mul)                  \
  X(Div, div)                  \
  X(Scale, scale)              \
  X(Relu, relu)                \
  X(HingeSq, hinge_sq)         \
  X(LayerNorm, layer_norm)     \
  X(ConcatCols, concat_cols)   \
  X(SliceCols, slice_cols)     \
  X(SumAll, sum_all)           \
  X(ColSum, col_sum)           \
  X(RowSum, row_sum)           \
  X(SquaredError, squared_error)
