#pragma once
// Reverse-mode tape over tensors (one node per tensor op, never per scalar).
//
// Forward: each op wrapper computes its result into the arena and, when the tape is
// recording and an input needs a gradient, appends a Node. Nodes are stored in
// construction order, which is a topological order, so backward is a plain reverse walk
// with one switch over OpKind (generated from op_list.h).
//
// Backward ADDS into input gradients. The caller zeroes parameter gradients between
// steps (ParamStore::zero_grads); tape tensors get zeroed gradients when created.
//
// Memory: values and saved intermediates live in the arena until reset(). Gradients of op
// outputs live in a GradRegion (autodiff/arena.h): committed only where backward writes, and
// given back as the walk passes the op that produced them, so after backward the gradients of
// intermediate tensors read as zero; leaves (leaf(), zeros(.., true)) and parameters keep theirs.
// Scratch that only backward uses is not allocated at forward time (each kernel keeps one
// reusable buffer; see ops_*.cpp).
//
// One step:   tape.reset(); ...forward ops...; tape.backward(loss); optimizer step.
// Rollout:    NoRecord guard(tape); ...forward ops... (no nodes, no gradient buffers).
#include "autodiff/arena.h"
#include "autodiff/check.h"
#include "autodiff/op_list.h"
#include "autodiff/op_params.h"
#include "autodiff/var.h"

#include <algorithm>
#include <array>
#include <cstdint>
#include <initializer_list>
#include <span>
#include <vector>

namespace layersnet::ad {

enum class OpKind : int32_t {
#define LAYERSNET_OP_ENUM(Enum, stem) Enum,
  LAYERSNET_ALL_OPS(LAYERSNET_OP_ENUM)
#undef LAYERSNET_OP_ENUM
      Count
};

constexpr int32_t kOpCount = static_cast<int32_t>(OpKind::Count);

// Number format of the products in linear / linear_relu (autodiff/bf16_gemm.h).
// kBFloat16 is for inference only: such an op on a recording tape throws.
enum class MatmulPrecision : int32_t { kFloat32, kBFloat16 };
const char* matmul_precision_name(MatmulPrecision p);  // "float32" | "bf16" (bf16_gemm.cpp)

const char* op_name(OpKind op);

// What backward needs of one op: its inputs, its output, its parameters (autodiff/op_params.h)
// and the forward intermediates it saved.
template <class T>
struct Node {
  OpKind op{};
  Var<T> out;
  std::array<Var<T>, 4> in{};
  OpParams<T> params;  // the struct of this op kind; std::monostate for ops without any
  T* saved = nullptr;  // in the arena; layout in each op's recording code
  // GradRegion offset before this op's output gradients: everything above is dead once this
  // node's backward has run.
  std::size_t grad_mark = 0;
};

// Where one step's time and memory go, per op kind (`layersnet bench model --profile`).
// Forward time of an op = wall time from the previous op's record (or from profiling start)
// to its own, so model code between ops counts towards the next op.
struct OpProfile {
  int64_t count = 0;
  double forward_ms = 0, backward_ms = 0;
  std::size_t arena_bytes = 0;  // values and saved intermediates allocated for the op (held until reset)
  std::size_t grad_bytes = 0;   // gradients of its outputs (committed only while backward needs them)
};
struct TapeProfile {
  std::array<OpProfile, kOpCount> ops{};
  std::size_t arena_bytes_end_of_forward = 0;  // values + saved, when backward starts
  std::size_t grad_bytes_reserved = 0;         // every op-output gradient of the step
};

template <class T>
class Tape {
 public:
  explicit Tape(std::size_t first_block_bytes = std::size_t{1} << 20) : arena_(first_block_bytes) {
    nodes_.reserve(1024);
  }

  Arena& arena() { return arena_; }
  bool recording() const { return recording_; }
  void set_recording(bool on) { recording_ = on; }
  // Kept across reset(); see MatmulPrecision.
  MatmulPrecision matmul_precision() const { return matmul_precision_; }
  void set_matmul_precision(MatmulPrecision p) { matmul_precision_ = p; }

  // A fresh (rows, cols) tensor; values uninitialised; gradient zeroed when `with_grad`
  // and the tape is recording, else null.
  Var<T> new_var(int64_t rows, int64_t cols, bool with_grad);
  // Copies `data` (rows*cols values, row-major) into the arena; no gradient.
  Var<T> constant(const T* data, int64_t rows, int64_t cols);
  // A leaf that needs a gradient (for checks and inputs we differentiate by).
  Var<T> leaf(const T* data, int64_t rows, int64_t cols);
  Var<T> zeros(int64_t rows, int64_t cols, bool with_grad = false);

  // Copies an array into the arena (nodes keep views, callers' vectors may die).
  template <class U>
  std::span<const U> copy_to_arena(std::span<const U> data) {
    U* p = arena_.allocate_array<U>(data.size());
    std::copy(data.begin(), data.end(), p);
    return {p, data.size()};
  }
  T* scratch(std::size_t count) { return arena_.allocate_array<T>(count); }

  // True when an op with these inputs must record a node and produce a gradient.
  bool wants_grad(std::initializer_list<Var<T>> inputs) const {
    if (!recording_) return profile_ != nullptr;  // profiling a no-grad forward: every op reports
    for (const auto& v : inputs)
      if (v.grad) return true;
    return false;
  }
  Node<T>& record(OpKind op, const Var<T>& out, std::initializer_list<Var<T>> inputs, OpParams<T> params = {});

  // Seeds d loss / d loss = 1 (loss must be 1x1) and walks the nodes backwards.
  void backward(const Var<T>& loss);
  // Walks the nodes backwards with output gradients already seeded by the caller.
  void backward_seeded();

  // Forgets every node and rewinds the arena; capacity is kept for the next step.
  void reset();

  const std::vector<Node<T>>& nodes() const { return nodes_; }
  const GradRegion& grad_region() const { return grads_; }

  // Profiling: times and bytes per op kind go into *p until set_profile(nullptr). With
  // profiling on, a non-recording tape answers wants_grad with true, so that every op calls
  // record() (timing only: no node, no gradient buffer); ops may then save what their
  // backward would need, which the profile counts.
  void set_profile(TapeProfile* p);
  bool profiling() const { return profile_ != nullptr; }

 private:
  void mark_profile(OpKind op, const Var<T>& out);
  T* leaf_grad(int64_t count);
  Arena arena_;
  GradRegion grads_;
  std::vector<Node<T>> nodes_;
  std::size_t grad_mark_ = 0;  // GradRegion top at the last record
  TapeProfile* profile_ = nullptr;
  double profile_clock_ms_ = 0;
  std::size_t profile_arena_ = 0;
  Node<T> profile_sink_;  // what record() returns when profiling a non-recording tape
  bool recording_ = true;
  MatmulPrecision matmul_precision_ = MatmulPrecision::kFloat32;
};

// Scope without recording (rollouts, evaluation, the no-grad part of noisy rollouts).
template <class T>
class NoRecord {
 public:
  explicit NoRecord(Tape<T>& tape) : tape_(tape), was_(tape.recording()) { tape.set_recording(false); }
  ~NoRecord() { tape_.set_recording(was_); }
  NoRecord(const NoRecord&) = delete;
  NoRecord& operator=(const NoRecord&) = delete;

 private:
  Tape<T>& tape_;
  bool was_;
};

// Scope with another matmul precision (e.g. bf16 inside a NoRecord rollout step).
template <class T>
class MatmulPrecisionScope {
 public:
  MatmulPrecisionScope(Tape<T>& tape, MatmulPrecision p) : tape_(tape), was_(tape.matmul_precision()) {
    tape.set_matmul_precision(p);
  }
  ~MatmulPrecisionScope() { tape_.set_matmul_precision(was_); }
  MatmulPrecisionScope(const MatmulPrecisionScope&) = delete;
  MatmulPrecisionScope& operator=(const MatmulPrecisionScope&) = delete;

 private:
  Tape<T>& tape_;
  MatmulPrecision was_;
};

// Backward of each op, defined next to its forward in ops_*.cpp.
#define LAYERSNET_OP_BACKWARD_DECL(Enum, stem) \
  template <class T>                           \
  void backward_##stem(const Node<T>& node);
LAYERSNET_ALL_OPS(LAYERSNET_OP_BACKWARD_DECL)
#undef LAYERSNET_OP_BACKWARD_DECL

extern template class Tape<float>;
extern template class Tape<double>;

}  // namespace layersnet::ad
