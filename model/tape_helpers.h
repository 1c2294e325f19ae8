#pragma once
// Model-side composites of tape ops: free views (reshape, row ranges), per-head reductions,
// MLPs and LayerNorms looked up by parameter name. No new ops: everything here records the
// ops of autodiff/ops_*.h (views record nothing: they alias the same value/grad memory, so
// backward of the consumer adds straight into the viewed tensor's gradient).
#include "autodiff/ops_dense.h"
#include "autodiff/ops_geometry.h"
#include "autodiff/ops_graph.h"
#include "autodiff/params.h"

#include <string>
#include <vector>

namespace layersnet::model {

using ad::Var;

// The same row-major memory seen as (rows, cols); rows * cols must equal x.size().
template <class T>
Var<T> view(const Var<T>& x, int64_t rows, int64_t cols) {
  LAYERSNET_CHECK(rows * cols == x.size(), "view (" << rows << ", " << cols << ") of a (" << x.rows << ", " << x.cols
                                                    << ") tensor");
  Var<T> v = x;
  v.rows = rows, v.cols = cols;
  return v;
}

// Rows [r0, r1) of x as a view (rows are contiguous in row-major memory).
template <class T>
Var<T> rows_of(const Var<T>& x, int64_t r0, int64_t r1) {
  LAYERSNET_CHECK(0 <= r0 && r0 <= r1 && r1 <= x.rows, "rows [" << r0 << ", " << r1 << ") of " << x.rows);
  Var<T> v = x;
  v.value = x.value + r0 * x.cols;
  if (x.grad) v.grad = x.grad + r0 * x.cols;
  v.rows = r1 - r0;
  return v;
}

// A constant (no gradient) from host data.
template <class T>
Var<T> constant(ad::Tape<T>& tape, const std::vector<T>& data, int64_t rows, int64_t cols) {
  LAYERSNET_CHECK(static_cast<int64_t>(data.size()) == rows * cols,
                  "constant of " << data.size() << " values as (" << rows << ", " << cols << ")");
  return tape.constant(data.data(), rows, cols);
}

// Per-head dot product: a, b (E, G*hd) -> (E, G) with out[e, g] = Σ_c a[e, g*hd + c] b[e, g*hd + c].
template <class T>
Var<T> head_dot(ad::Tape<T>& tape, const Var<T>& a, const Var<T>& b, int64_t heads) {
  const Var<T> p = ad::mul(tape, a, b);
  const int64_t hd = a.cols / heads;
  return view(ad::row_sum(tape, view(p, a.rows * heads, hd)), a.rows, heads);
}

// Per-head norm: x (E, G*hd) -> (E, G) with out[e, g] = ‖x[e, g-th head]‖.
template <class T>
Var<T> head_norm(ad::Tape<T>& tape, const Var<T>& x, int64_t heads) {
  const int64_t hd = x.cols / heads;
  return view(ad::row_norm(tape, view(x, x.rows * heads, hd)), x.rows, heads);
}

// Per-head scaling: w (E, G), x (E, G*hd) -> (E, G*hd), head g of row e times w[e, g].
template <class T>
Var<T> head_scale(ad::Tape<T>& tape, const Var<T>& w, const Var<T>& x, int64_t heads) {
  const int64_t hd = x.cols / heads;
  return view(ad::mul(tape, view(x, x.rows * heads, hd), view(w, x.rows * heads, 1)), x.rows, x.cols);
}

// Parameter lookup with the store's error message for unknown names.
template <class T>
struct ParamView {
  ad::ParamStore<T>& store;
  Var<T> operator()(const std::string& name) const { return store.var(name); }
  bool has(const std::string& name) const {
    for (const auto& e : store.entries())
      if (e.name == name) return true;
    return false;
  }
};

// MLP "prefix.{i}.{weight,bias}" of n linears, ReLU between them and, if final_relu, after the last.
// One fused op (ad::mlp): the hidden rows stay in cache.
template <class T>
Var<T> mlp(ad::Tape<T>& tape, const ParamView<T>& p, const std::string& prefix, int n, bool final_relu, const Var<T>& x,
           bool bias = true) {
  std::vector<Var<T>> weights, biases;
  for (int i = 0; i < n; ++i) {
    const std::string k = prefix + "." + std::to_string(i);
    weights.push_back(p(k + ".weight"));
    biases.push_back(bias ? p(k + ".bias") : Var<T>{});
  }
  return ad::mlp(tape, x, std::span<const Var<T>>(weights), std::span<const Var<T>>(biases), final_relu);
}

template <class T>
Var<T> norm(ad::Tape<T>& tape, const ParamView<T>& p, const std::string& prefix, const Var<T>& x) {
  return ad::layer_norm(tape, x, p(prefix + ".weight"), p(prefix + ".bias"));
}

}  // namespace layersnet::model
