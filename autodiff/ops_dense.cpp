#include "autodiff/ops_dense.h"

namespace layersnet::ad {

namespace {

// b broadcast to a's (N, C): b is (N, C), (1, C), (N, 1) or (1, 1).
template <class T>
void check_broadcast(const char* op, const Var<T>& a, const Var<T>& b) {
  LAYERSNET_CHECK((b.rows == a.rows || b.rows == 1) && (b.cols == a.cols || b.cols == 1),
                  op << ": cannot broadcast (" << b.rows << ", " << b.cols << ") to (" << a.rows << ", "
                     << a.cols << ")");
}

// Reduces a (N, C) gradient onto b's broadcast shape and adds it to gb.
template <class T>
void accumulate_broadcast(const Eigen::Ref<const RowMat<T>>& g, Var<T> b) {
  auto gb = b.grd();
  if (b.rows == g.rows() && b.cols == g.cols()) gb += g;
  else if (b.rows == 1 && b.cols == g.cols()) gb += g.colwise().sum();
  else if (b.cols == 1 && b.rows == g.rows()) gb += g.rowwise().sum();
  else gb(0, 0) += g.sum();
}

template <class T>
auto broadcast_view(const Var<T>& b, int64_t rows, int64_t cols) {
  return b.val().replicate(rows / b.rows, cols / b.cols);
}

}  // namespace

// ---- add --------------------------------------------------------------------------------
template <class T>
Var<T> add(Tape<T>& tape, const Var<T>& a, const Var<T>& b) {
  check_broadcast("add", a, b);
  const bool grad = tape.wants_grad({a, b});
  Var<T> out = tape.new_var(a.rows, a.cols, grad);
  out.val() = a.val() + broadcast_view(b, a.rows, a.cols);
  if (grad) tape.record(OpKind::Add, out, {a, b});
  return out;
}

template <class T>
void backward_add(const Node<T>& node) {
  const auto& [a, b, unused2, unused3] = node.in;
  if (a.grad) a.grd() += node.out.grd();
  if (b.grad) accumulate_broadcast<T>(node.out.grd(), b);
}

#define LAYERSNET_INSTANTIATE(T)                                       \
  template Var<T> add<T>(Tape<T>&, const Var<T>&, const Var<T>&);     \
  template void backward_add<T>(const Node<T>&);
LAYERSNET_INSTANTIATE(float)
LAYERSNET_INSTANTIATE(double)
#undef LAYERSNET_INSTANTIATE

}  // namespace layersnet::ad
