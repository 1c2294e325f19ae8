#include "autodiff/tape.h"

#include "autodiff/row_blocks.h"

#include <algorithm>
#include <chrono>
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
  // Zero without a pass over memory: the region's pages read as zero until written.
  if (with_grad && recording_) v.grad = static_cast<T*>(grads_.allocate(sizeof(T) * static_cast<std::size_t>(rows * cols)));
  return v;
}

namespace {
double clock_ms() {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now().time_since_epoch()).count();
}
}  // namespace

template <class T>
void Tape<T>::set_profile(TapeProfile* p) {
  profile_ = p;
  profile_clock_ms_ = clock_ms();
  profile_arena_ = arena_.bytes_in_use();
  grad_mark_ = grads_.top();
}

template <class T>
void Tape<T>::mark_profile(OpKind op, const Var<T>& out) {
  (void)out;
  OpProfile& o = profile_->ops[static_cast<std::size_t>(op)];
  const double now = clock_ms();
  const std::size_t arena = arena_.bytes_in_use();
  ++o.count;
  o.forward_ms += now - profile_clock_ms_;
  o.arena_bytes += arena - profile_arena_;
  o.grad_bytes += grads_.top() - grad_mark_;
  profile_clock_ms_ = now;
  profile_arena_ = arena;
}

template <class T>
Var<T> Tape<T>::constant(const T* data, int64_t rows, int64_t cols) {
  Var<T> v = new_var(rows, cols, false);
  if (rows * cols > 0) std::memcpy(v.value, data, sizeof(T) * static_cast<std::size_t>(rows * cols));
  return v;
}

template <class T>
Var<T> Tape<T>::leaf(const T* data, int64_t rows, int64_t cols) {
  Var<T> v = new_var(rows, cols, false);
  if (rows * cols > 0) std::memcpy(v.value, data, sizeof(T) * static_cast<std::size_t>(rows * cols));
  if (recording_) v.grad = leaf_grad(rows * cols);
  return v;
}

template <class T>
Var<T> Tape<T>::zeros(int64_t rows, int64_t cols, bool with_grad) {
  Var<T> v = new_var(rows, cols, false);
  std::fill_n(v.value, rows * cols, T(0));
  if (with_grad && recording_) v.grad = leaf_grad(rows * cols);
  return v;
}

// The caller reads a leaf's gradient after backward: it lives in the arena, not the region.
template <class T>
T* Tape<T>::leaf_grad(int64_t count) {
  T* g = arena_.allocate_array<T>(static_cast<std::size_t>(count));
  std::fill_n(g, count, T(0));
  return g;
}

template <class T>
Node<T>& Tape<T>::record(OpKind op, const Var<T>& out, std::initializer_list<Var<T>> inputs, OpParams<T> params) {
  LAYERSNET_CHECK(inputs.size() <= 4, "an op records at most 4 inputs; pass more in its params (as concat_cols)");
  if (profile_) mark_profile(op, out);
  if (!recording_) return profile_sink_;  // profiling a no-grad forward: timing only
  Node<T>& node = nodes_.emplace_back();
  node.op = op;
  node.out = out;
  node.params = std::move(params);
  node.grad_mark = grad_mark_;
  grad_mark_ = grads_.top();
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
  if (profile_) {
    profile_->arena_bytes_end_of_forward = arena_.bytes_in_use();
    profile_->grad_bytes_reserved = grads_.top();
  }
  for (auto it = nodes_.rbegin(); it != nodes_.rend(); ++it) {
    const Node<T>& node = *it;
    // Gradients above this node's mark belong to ops at or after it: all of them have run.
    struct ReleaseAfter {
      GradRegion& region;
      std::size_t mark;
      ~ReleaseAfter() { region.release_from(mark); }
    } release{grads_, node.grad_mark};
    if (!node.out.grad) continue;
    const double t0 = profile_ ? clock_ms() : 0;
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
    if (profile_) profile_->ops[static_cast<std::size_t>(node.op)].backward_ms += clock_ms() - t0;
  }
}

template <class T>
void Tape<T>::reset() {
  nodes_.clear();
  arena_.rewind();
  grads_.rewind();
  grad_mark_ = 0;
  if (profile_) set_profile(profile_);  // the step starts here: marks back to the empty tape
}

template class Tape<float>;
template class Tape<double>;

}  // namespace layersnet::ad
