#pragma once
// A tensor on the tape: a row-major (rows, cols) view of values and, when somebody needs
// it, of the gradient. Memory belongs to the tape's arena or to a ParamStore.
//
// grad == nullptr means "no gradient needed": backward skips it (constants, data, and
// everything while the tape is not recording).
#include <Eigen/Core>

#include <cstdint>

namespace layersnet::ad {

template <class T>
using RowMat = Eigen::Matrix<T, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
template <class T>
using MatMap = Eigen::Map<RowMat<T>>;
template <class T>
using ConstMatMap = Eigen::Map<const RowMat<T>>;

template <class T>
struct Var {
  T* value = nullptr;  // (rows, cols), row-major
  T* grad = nullptr;   // (rows, cols) or nullptr
  int64_t rows = 0;
  int64_t cols = 0;

  int64_t size() const { return rows * cols; }
  bool needs_grad() const { return grad != nullptr; }
  Eigen::Map<RowMat<T>> val() const { return {value, rows, cols}; }
  Eigen::Map<RowMat<T>> grd() const { return {grad, rows, cols}; }
  T scalar() const { return value[0]; }
};

}  // namespace layersnet::ad
