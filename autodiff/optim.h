#pragma once
// Adam (torch.optim.Adam semantics, amsgrad off) over the flat buffers of a ParamStore:
// values, grads and the two moments are four arrays of equal length, so one step is one
// elementwise pass. Elementwise and free of reductions, the update is bit-identical for
// any thread count; the step count t (for bias correction) is the only extra state.
//
//   g  = grad + weight_decay * p                       (L2 form, as torch; default 0)
//   m  = beta1 m + (1 - beta1) g
//   v  = beta2 v + (1 - beta2) g²
//   p -= lr / (1 - beta1^t) * m / (sqrt(v) / sqrt(1 - beta2^t) + eps)
//
// Usage per training step: params.zero_grads(); forward; tape.backward(loss); adam.step().
// Resume: restore values and moments (ParamStore::moment1/2), then set_step_count(t).
#include "autodiff/params.h"

#include <cstdint>

namespace layersnet::ad {

struct AdamOptions {
  double lr = 1e-3;  // official schedule starts at 1e-3 and halves by epoch steps
  double beta1 = 0.9;
  double beta2 = 0.999;
  double eps = 1e-8;
  double weight_decay = 0;
};

template <class T>
class Adam {
 public:
  explicit Adam(ParamStore<T>& params, const AdamOptions& options = {});

  // One update from params.grads(); increments the step count first (t starts at 1).
  void step();

  int64_t step_count() const { return t_; }
  void set_step_count(int64_t t);  // after restoring the moments from a checkpoint
  void set_lr(double lr) { options_.lr = lr; }
  const AdamOptions& options() const { return options_; }

 private:
  ParamStore<T>& params_;
  AdamOptions options_;
  int64_t t_ = 0;
};

// sqrt(Σ grad²) over every parameter, accumulated in double in a fixed order (for logging
// and for spotting exploding gradients); deterministic for any thread count.
template <class T>
double grad_norm(const ParamStore<T>& params);

extern template class Adam<float>;
extern template class Adam<double>;

}  // namespace layersnet::ad
