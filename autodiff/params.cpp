#include "autodiff/params.h"

#include "autodiff/check.h"

#include <algorithm>

namespace layersnet::ad {

template <class T>
int ParamStore<T>::add(const std::string& name, int64_t rows, int64_t cols) {
  LAYERSNET_CHECK(!finalized_, "parameter '" << name << "' added after finalize()");
  LAYERSNET_CHECK(rows > 0 && cols > 0, "parameter '" << name << "' has shape (" << rows << ", " << cols << ")");
  LAYERSNET_CHECK(!by_name_.count(name), "parameter '" << name << "' registered twice");
  const int index = static_cast<int>(entries_.size());
  // Pad offsets to 16 elements so every tensor starts on a 64-byte boundary for floats.
  total_ = (total_ + 15) / 16 * 16;
  entries_.push_back({name, total_, rows, cols});
  by_name_[name] = index;
  total_ += static_cast<std::size_t>(rows * cols);
  return index;
}

template <class T>
void ParamStore<T>::finalize() {
  LAYERSNET_CHECK(!finalized_, "finalize() called twice");
  values_.assign(total_, T(0));
  grads_.assign(total_, T(0));
  m1_.assign(total_, T(0));
  m2_.assign(total_, T(0));
  finalized_ = true;
}

template <class T>
int ParamStore<T>::find(const std::string& name) const {
  const auto it = by_name_.find(name);
  return it == by_name_.end() ? -1 : it->second;
}

template <class T>
int ParamStore<T>::index_of(const std::string& name) const {
  if (const int i = find(name); i >= 0) return i;
  // Name the closest parameter: the longest common prefix is a good enough guess.
  std::string best;
  std::size_t best_len = 0;
  for (const auto& e : entries_) {
    const auto mismatch = std::mismatch(name.begin(), name.end(), e.name.begin(), e.name.end());
    const auto len = static_cast<std::size_t>(mismatch.first - name.begin());
    if (len >= best_len) best_len = len, best = e.name;
  }
  LAYERSNET_CHECK(false, "no parameter named '" << name << "'" << (best.empty() ? "" : "; closest: '" + best + "'"));
  return -1;
}

template <class T>
Var<T> ParamStore<T>::var(int index) {
  LAYERSNET_CHECK(finalized_, "ParamStore::var() before finalize()");
  const ParamEntry& e = entries_.at(static_cast<std::size_t>(index));
  Var<T> v;
  v.value = values_.data() + e.offset;
  v.grad = grads_.data() + e.offset;
  v.rows = e.rows;
  v.cols = e.cols;
  return v;
}

template <class T>
std::span<T> ParamStore<T>::value(int index) {
  const ParamEntry& e = entries_.at(static_cast<std::size_t>(index));
  return std::span<T>(values_).subspan(e.offset, static_cast<std::size_t>(e.size()));
}

template <class T>
void ParamStore<T>::zero_grads() {
  std::fill(grads_.begin(), grads_.end(), T(0));
}

template class ParamStore<float>;
template class ParamStore<double>;

}  // namespace layersnet::ad
