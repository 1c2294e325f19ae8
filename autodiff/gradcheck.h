#pragma once
// Gradient checks in double precision (dlib / PyTorch gradcheck style).
//
// For f: inputs -> Y, checks one scalar L = <R, Y> with a fixed random R: the tape's
// vector-Jacobian product against central differences (L(x+eps) - L(x-eps)) / 2eps on
// every coordinate (or a random sample of max_coords per input). Passes when
// |ad - fd| <= atol + rtol * |fd| everywhere. Gradient buffers are pre-filled with
// `prefill` before backward, which proves backward adds instead of overwriting.
// Also checks that outputs and gradients are finite, and that the no-record forward
// gives bit-identical outputs.
#include "autodiff/tape.h"

#include <functional>
#include <set>
#include <string>
#include <vector>

namespace layersnet::ad {

struct GradcheckOptions {
  double eps = 1e-6;
  double atol = 1e-6;
  double rtol = 1e-5;
  int max_coords = 96;  // per input; larger inputs are sampled
  unsigned seed = 20231001;
  double prefill = 9.0;
};

struct GradcheckInput {
  RowMat<double> value;
  bool needs_grad = true;
};

struct GradcheckReport {
  bool ok = true;
  bool finite = true;
  double max_abs_error = 0;
  int coords_checked = 0;
  std::string failures;      // one line per failed coordinate (first few)
  std::set<OpKind> ops_seen;  // ops recorded on the tape
  RowMat<double> output;
  std::vector<RowMat<double>> gradients;  // analytic, per input (empty if not needed)
};

using GradcheckFn = std::function<Var<double>(Tape<double>&, const std::vector<Var<double>>&)>;

GradcheckReport gradcheck(const GradcheckFn& f, const std::vector<GradcheckInput>& inputs,
                          const GradcheckOptions& options = {});

// Whole-model check: one random direction d over all inputs needing grad (JAX check_grads):
// <grad L, d> against (L(x + eps d) - L(x - eps d)) / 2eps. f must return a 1x1 loss.
struct DirectionalReport {
  double analytic = 0;
  double numeric = 0;
  bool ok = false;
};
DirectionalReport directional_gradcheck(const GradcheckFn& f, const std::vector<GradcheckInput>& inputs,
                                        const GradcheckOptions& options = {});

}  // namespace layersnet::ad
