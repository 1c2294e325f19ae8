#pragma once
// Parameters, their gradients and Adam's two moments as four flat buffers of equal
// length, plus one name table {name, offset, rows, cols} (llm.c / dlib layout).
// Names follow the module path: "encoder.layers.0.attn.q_proj.weight".
//
// Usage: add() every tensor, then finalize(); var(i) gives a tape leaf that points into
// the flat buffers, so backward accumulates straight into grads().
#include "autodiff/var.h"

#include <cstdint>
#include <span>
#include <string>
#include <unordered_map>
#include <vector>

namespace layersnet::ad {

struct ParamEntry {
  std::string name;
  std::size_t offset = 0;  // into the flat buffers, in elements
  int64_t rows = 0;
  int64_t cols = 0;
  int64_t size() const { return rows * cols; }
};

template <class T>
class ParamStore {
 public:
  // Registers a (rows, cols) tensor; returns its index. Only before finalize().
  int add(const std::string& name, int64_t rows, int64_t cols);
  // Allocates the flat buffers (values zero; initialise them afterwards).
  void finalize();
  bool finalized() const { return finalized_; }

  int index_of(const std::string& name) const;  // throws with the closest names if unknown
  int find(const std::string& name) const;      // -1 if unknown
  const std::vector<ParamEntry>& entries() const { return entries_; }
  std::size_t total_size() const { return total_; }

  // A leaf for the tape: values and gradient inside the flat buffers.
  Var<T> var(int index);
  Var<T> var(const std::string& name) { return var(index_of(name)); }
  std::span<T> value(int index);  // one tensor's values

  std::span<T> values() { return values_; }
  std::span<T> grads() { return grads_; }
  std::span<T> moment1() { return m1_; }
  std::span<T> moment2() { return m2_; }
  std::span<const T> values() const { return values_; }
  std::span<const T> grads() const { return grads_; }
  std::span<const T> moment1() const { return m1_; }
  std::span<const T> moment2() const { return m2_; }

  void zero_grads();

 private:
  std::vector<ParamEntry> entries_;
  std::unordered_map<std::string, int> by_name_;
  std::size_t total_ = 0;
  bool finalized_ = false;
  std::vector<T> values_, grads_, m1_, m2_;
};

extern template class ParamStore<float>;
extern template class ParamStore<double>;

}  // namespace layersnet::ad
