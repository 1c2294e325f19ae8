#include "losses/losses.h"

#include "autodiff/ops_cloth.h"
#include "dataset/neighbours.h"
#include "dataset/patches.h"
#include "model/params_layout.h"
#include "model/tape_helpers.h"

#include <algorithm>
#include <cmath>

namespace layersnet::losses {
namespace {

using ad::Var;

// Rows [r0, r1) of a (rows, 3) array as float points for the k-d tree.
template <class T>
dataset::Points points(const T* xyz, int64_t r0, int64_t r1, int64_t stride) {
  dataset::Points out(r1 - r0, 3);
  for (int64_t i = r0; i < r1; ++i)
    for (int c = 0; c < 3; ++c) out(i - r0, c) = static_cast<float>(xyz[i * stride + c]);
  return out;
}

// Eq. 18 for the query points `x` (Q, 3) against anchors: anchor position and normal per
// query (constants or tape tensors of (Q, 3)). Returns Σ min(d − eps, 0)² / max(N_c, 1), or / Q
// with over_all_rows (loss.layer_mean_over = "outer").
template <class T>
Var<T> collision_term(ad::Tape<T>& tape, const Var<T>& x, const Var<T>& anchor, const Var<T>& normal, T eps,
                      bool over_all_rows, int64_t& count) {
  const Var<T> d = ad::row_sum(tape, ad::mul(tape, ad::sub(tape, x, anchor), normal));  // (Q, 1)
  const Var<T> pen = ad::hinge_sq(tape, d, eps);
  count = 0;
  for (int64_t i = 0; i < pen.rows; ++i) count += pen.value[i] > T(0);
  const int64_t divisor = over_all_rows ? pen.rows : count;
  return ad::scale(tape, ad::sum_all(tape, pen), T(1) / static_cast<T>(std::max<int64_t>(divisor, 1)));
}

}  // namespace

template <class T>
void set_target_edges(LossInput<T>& L) {
  const dataset::Faces faces =
      Eigen::Map<const dataset::Faces>(L.faces.data(), static_cast<Eigen::Index>(L.faces.size() / 3), 3);
  L.edges.clear();
  L.target_edge_length.clear();
  for (const auto& [a, b] : dataset::mesh_edges(faces)) {
    double len2 = 0;
    for (int c = 0; c < 3; ++c) {
      const double d = static_cast<double>(L.target[3 * a + c]) - static_cast<double>(L.target[3 * b + c]);
      len2 += d * d;
    }
    L.edges.push_back(a);
    L.edges.push_back(b);
    L.target_edge_length.push_back(static_cast<T>(std::sqrt(len2)));
  }
}

// Mean squared error of the zero-output prediction x − a (columns 0–2 minus 6–8 of a (n, 9)
// prediction) against target (n, 3), floored at (1 mm)² = 1e-4 units² per coordinate; 1 when not relative.
template <class T>
double base_error(const Var<T>& pred, const std::vector<T>& target, bool relative) {
  if (!relative) return 1.0;
  double sum = 0;
  for (int64_t i = 0; i < pred.rows; ++i)
    for (int c = 0; c < 3; ++c) {
      const double d = static_cast<double>(pred.value[9 * i + c]) - pred.value[9 * i + 6 + c] - target[3 * i + c];
      sum += d * d;
    }
  return std::max(sum / static_cast<double>(3 * std::max<int64_t>(1, pred.rows)), 1e-4);
}

template <class T>
LossTerms<T> compute_losses(ad::Tape<T>& tape, ad::ParamStore<T>& params, const ModelConfig& mc, const LossConfig& lc,
                            const LossInput<T>& tg, const model::Predictions<T>& pred) {
  const int64_t N = pred.vertex.rows, P = pred.patch.rows;
  LAYERSNET_CHECK(static_cast<int64_t>(tg.target.size()) == 3 * N && static_cast<int64_t>(tg.target_patch.size()) == 3 * P,
                  "LossInput target (N, 3) / target_patch (P, 3) do not match the predictions (N = " << N << ", P = " << P
                                                                                                     << ")");
  LossTerms<T> out;
  std::vector<Var<T>> weighted;
  auto add_term = [&](const Var<T>& term, double weight, double& value) {
    value = static_cast<double>(term.scalar());
    weighted.push_back(ad::scale(tape, term, static_cast<T>(weight)));
  };
  const Var<T> x = ad::slice_cols(tape, pred.vertex, 0, 3);
  if (lc.vertex != 0)
    add_term(ad::mean_all(tape, ad::squared_error(tape, x, model::constant(tape, tg.target, N, 3))),
             lc.vertex / base_error(pred.vertex, tg.target, lc.relative_to_base), out.vertex);
  if (lc.patch != 0)
    add_term(ad::mean_all(tape, ad::squared_error(tape, ad::slice_cols(tape, pred.patch, 0, 3),
                                                  model::constant(tape, tg.target_patch, P, 3))),
             lc.patch / base_error(pred.patch, tg.target_patch, lc.relative_to_base), out.patch);
  const int64_t G = static_cast<int64_t>(tg.garment_offsets.size()) - 1;
  const bool layer_term = lc.collision_layer != 0 && G >= 2;
  Var<T> normals;
  if (lc.normal != 0 || layer_term) normals = ad::vertex_normals(tape, x, std::span<const int32_t>(tg.faces));
  if (lc.normal != 0)
    add_term(ad::mean_all(tape, ad::squared_error(tape, normals, model::constant(tape, tg.target_normals, N, 3))),
             lc.normal, out.normal);
  const T eps = static_cast<T>(lc.collision_eps);
  if (lc.collision_body != 0) {
    const int64_t B = static_cast<int64_t>(tg.body_pos.size() / 3);
    const auto idx = dataset::nearest_body(points(pred.vertex.value, 0, N, 9), points(tg.body_pos.data(), 0, B, 3)).index;
    const Var<T> h = ad::gather_rows(tape, model::constant(tape, tg.body_pos, B, 3), idx);
    const Var<T> n = ad::gather_rows(tape, model::constant(tape, tg.body_normals, B, 3), idx);
    add_term(collision_term(tape, x, h, n, eps, false, out.body_collisions), lc.collision_body, out.collision_body);
  }
  if (layer_term) {
    const int64_t o0 = tg.garment_offsets[G - 1], o1 = tg.garment_offsets[G];
    // Indices into the inner vertices [0, o0) = global vertex ids.
    const auto idx = dataset::nearest_body(points(pred.vertex.value, o0, o1, 9), points(pred.vertex.value, 0, o0, 9)).index;
    const Var<T> xo = model::rows_of(x, o0, o1);
    add_term(collision_term(tape, xo, ad::gather_rows(tape, x, idx), ad::gather_rows(tape, normals, idx), eps,
                            lc.layer_mean_over == "outer", out.layer_collisions),
             lc.collision_layer, out.collision_layer);
  }
  if (lc.edge_strain != 0 && !tg.edges.empty()) {
    const int64_t E = static_cast<int64_t>(tg.target_edge_length.size());
    std::vector<int32_t> ends[2];
    std::vector<T> inverse_length(E), ones(E, T(1));
    for (int64_t e = 0; e < E; ++e) {
      ends[0].push_back(tg.edges[2 * e]);
      ends[1].push_back(tg.edges[2 * e + 1]);
      // A degenerate ground-truth edge would give an infinite weight: floor it at 1e-6 units.
      inverse_length[e] = T(1) / std::max(tg.target_edge_length[e], T(1e-6));
    }
    const Var<T> length = ad::row_norm(tape, ad::sub(tape, ad::gather_rows(tape, x, ends[0]), ad::gather_rows(tape, x, ends[1])));
    const Var<T> ratio = ad::mul(tape, length, model::constant(tape, inverse_length, E, 1));
    add_term(ad::mean_all(tape, ad::squared_error(tape, ratio, model::constant(tape, ones, E, 1))), lc.edge_strain,
             out.edge_strain);
  }
  const auto rot_names = model::rotation_map_names(mc);
  // With model.orthogonality = "exact" the constraint holds by construction: no penalty.
  if (lc.orthogonality != 0 && !rot_names.empty() && mc.orthogonality != "exact") {
    auto identity = [&](int64_t n) {
      std::vector<T> eye(n * n, T(0));
      for (int64_t i = 0; i < n; ++i) eye[i * n + i] = T(1);
      return model::constant(tape, eye, n, n);
    };
    std::vector<Var<T>> parts;
    for (const auto& name : rot_names) {
      const Var<T> W = params.var(name);  // (d, c), c = 3 (simulator) or 3k (decoder)
      const Var<T> Ic = identity(W.cols);
      const Var<T> Wt = ad::linear(tape, Ic, W);  // (c, d)
      parts.push_back(ad::sum_all(tape, ad::squared_error(tape, ad::linear(tape, W, W), identity(W.rows))));
      parts.push_back(ad::sum_all(tape, ad::squared_error(tape, ad::linear(tape, Wt, Wt), Ic)));
    }
    Var<T> orth = parts[0];
    for (std::size_t k = 1; k < parts.size(); ++k) orth = ad::add(tape, orth, parts[k]);
    add_term(orth, lc.orthogonality, out.orthogonality);
  }
  LAYERSNET_CHECK(!weighted.empty(), "every loss weight is 0 (LossConfig): nothing to train");
  out.total = weighted[0];
  for (std::size_t k = 1; k < weighted.size(); ++k) out.total = ad::add(tape, out.total, weighted[k]);
  return out;
}

template void set_target_edges(LossInput<float>&);
template void set_target_edges(LossInput<double>&);
template LossTerms<float> compute_losses(ad::Tape<float>&, ad::ParamStore<float>&, const ModelConfig&, const LossConfig&,
                                         const LossInput<float>&, const model::Predictions<float>&);
template LossTerms<double> compute_losses(ad::Tape<double>&, ad::ParamStore<double>&, const ModelConfig&,
                                          const LossConfig&, const LossInput<double>&, const model::Predictions<double>&);

}  // namespace layersnet::losses
