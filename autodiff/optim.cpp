#include "autodiff/optim.h"

#include "autodiff/check.h"
#include "autodiff/row_blocks.h"

#include <cmath>

namespace layersnet::ad {

template <class T>
Adam<T>::Adam(ParamStore<T>& params, const AdamOptions& options) : params_(params), options_(options) {
  LAYERSNET_CHECK(params.finalized(), "Adam: construct it after ParamStore::finalize()");
  LAYERSNET_CHECK(options.lr >= 0 && options.eps > 0 && options.beta1 >= 0 && options.beta1 < 1 &&
                      options.beta2 >= 0 && options.beta2 < 1,
                  "Adam: need lr >= 0, eps > 0 and betas in [0, 1); got lr " << options.lr << ", betas ("
                      << options.beta1 << ", " << options.beta2 << "), eps " << options.eps);
}

template <class T>
void Adam<T>::set_step_count(int64_t t) {
  LAYERSNET_CHECK(t >= 0, "Adam: step count " << t << " < 0");
  t_ = t;
}

template <class T>
void Adam<T>::step() {
  ++t_;
  // Scalars in double: beta^t underflows gracefully and 1 - beta2^t keeps its digits.
  const double bc1 = 1.0 - std::pow(options_.beta1, static_cast<double>(t_));
  const double bc2 = 1.0 - std::pow(options_.beta2, static_cast<double>(t_));
  const T step_size = static_cast<T>(options_.lr / bc1);
  const T inv_sqrt_bc2 = static_cast<T>(1.0 / std::sqrt(bc2));
  const T b1 = static_cast<T>(options_.beta1), b2 = static_cast<T>(options_.beta2);
  const T eps = static_cast<T>(options_.eps), wd = static_cast<T>(options_.weight_decay);
  T* p = params_.values().data();
  const T* g = params_.grads().data();
  T* m = params_.moment1().data();
  T* v = params_.moment2().data();
  const auto n = static_cast<int64_t>(params_.total_size());
  for_row_blocks(n, 1, [&](int64_t i0, int64_t len) {
    for (int64_t i = i0; i < i0 + len; ++i) {
      const T gi = g[i] + wd * p[i];
      m[i] = b1 * m[i] + (T(1) - b1) * gi;
      v[i] = b2 * v[i] + (T(1) - b2) * gi * gi;
      p[i] -= step_size * m[i] / (std::sqrt(v[i]) * inv_sqrt_bc2 + eps);
    }
  });
}

template <class T>
double grad_norm(const ParamStore<T>& params) {
  const T* g = params.grads().data();
  const auto n = static_cast<int64_t>(params.total_size());
  const double* s = reduce_row_blocks<double>(n, 1, 1, [&](int64_t i0, int64_t len, double* acc) {
    for (int64_t i = i0; i < i0 + len; ++i) *acc += static_cast<double>(g[i]) * static_cast<double>(g[i]);
  });
  return std::sqrt(s[0]);
}

template class Adam<float>;
template class Adam<double>;
template double grad_norm<float>(const ParamStore<float>&);
template double grad_norm<double>(const ParamStore<double>&);

}  // namespace layersnet::ad
