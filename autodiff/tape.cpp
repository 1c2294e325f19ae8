#include "autodiff/tape.h"

#include "autodiff/row_blocks.h"

#include <algorithm>
#include <cstring>

namespace layersnet::ad {

const char* op_name(OpKind op) {
  switch (op) {
#define LAYERSNET_OP_NAME(Enum, stem) \
  case OpKind::Enum:                  \
    return #Enum;
    LAYERSNET_ALL_OPS(LAYERSNET_OP_NAME)
#undef LAYERSNET_OP_NAME
    case OpKind::Count:
      break;
  }
  return "?";
}

template <class T>
Var<T> Tape<T>::new_var(int64_t rows, int64_t cols, bool with_grad) {
  LAYERSNET_CHECK(rows >= 0 && cols >= 0, "tensor shape (" << rows << ", " << cols << ")");
  Var<T> v;
  v.rows = rows;
  v.cols = cols;
  v.value = arena_.allocate_array<T>(static_cast<std::size_t>(rows * cols));
  if (with_grad && recording_) {
    v.grad = arena_.allocate_array<T>(static_cast<std::size_t>(rows * cols));
    // Zeroing is a full memory pass (10% of a linear layer's forward at N = 80,000):
    // split it over the threads for large tensors.
    T* g = v.grad;
    for_row_blocks(rows * cols, 1, [g](int64_t i0, int64_t n) { std::fill_n(g + i0, n, T(0)); });
  }
  return v;
}

template <class T>
Var<T> Tape<T>::constant(const T* data, int64_t rows, int64_t cols) {
  Var<T> v = new_var(rows, cols, false);
  if (rows * cols > 0) std::memcpy(v.value, data, sizeof(T) * static_cast<std::size_t>(rows * cols));
  return v;
}

template <class T>
Var<T> Tape<T>::leaf(const T* data, int64_t rows, int64_t cols) {
  Var<T> v = new_var(rows, cols, true);
  if (rows * cols > 0) std::memcpy(v.value, data, sizeof(T) * static_cast<std::size_t>(rows * cols));
  return v;
}

template <class T>
Var<T> Tape<T>::zeros(int64_t rows, int64_t cols, bool with_grad) {
  Var<T> v = new_var(rows, cols, with_grad);
  std::fill_n(v.value, rows * cols, T(0));
  return v;
}

template <class T>
Node<T>& Tape<T>::record(OpKind op, const Var<T>& out, std::initializer_list<Var<T>> inputs, OpParams<T> params) {
  LAYERSNET_CHECK(inputs.size() <= 4, "an op records at most 4 inputs; pass more in its params (as concat_cols)");
  Node<T>& node = nodes_.emplace_back();
  node.op = op;
  node.out = out;
  node.params = std::move(params);
  std::size_t k = 0;
  for (const auto& v : inputs) node.in[k++] = v;
  return node;
}

template <class T>
void Tape<T>::backward(const Var<T>& loss) {
  LAYERSNET_CHECK(loss.rows == 1 && loss.cols == 1,
                  "backward(loss) needs a 1x1 loss, got (" << loss.rows << ", " << loss.cols << ")");
  LAYERSNET_CHECK(loss.grad != nullptr, "the loss does not depend on anything that needs a gradient "
                                        "(was the tape recording?)");
  loss.grad[0] += T(1);
  backward_seeded();
}

template <class T>
void Tape<T>::backward_seeded() {
  for (auto it = nodes_.rbegin(); it != nodes_.rend(); ++it) {
    const Node<T>& node = *it;
    if (!node.out.grad) continue;
    switch (node.op) {
#define LAYERSNET_OP_DISPATCH(Enum, stem) \
  case OpKind::Enum:                      \
    backward_##stem<T>(node);             \
    break;
      LAYERSNET_ALL_OPS(LAYERSNET_OP_DISPATCH)
#undef LAYERSNET_OP_DISPATCH
      case OpKind::Count:
        LAYERSNET_CHECK(false, "corrupt node on the tape");
    }
  }
}

template <class T>
void Tape<T>::reset() {
  nodes_.clear();
  arena_.rewind();
}

template class Tape<float>;
template class Tape<double>;

}  // namespace layersnet::ad
