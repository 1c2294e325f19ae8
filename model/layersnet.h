#pragma once
// The LayersNet forward pass (paper §3, official wiring: reference §2; decisions in
// model/README.md) on the reverse-mode tape.
//
//   tokens     patch tokens   FFN_in(mean normalised member states)            (P, d)
//              attr tokens    FFN_attr(attr)                                   (A, d)
//              body tokens    FFN_in(normalised body state)                    (U, d)
//              wind token     FFN_wind(wind) — only if the scene has wind      (1, d)
//              gravity token  FFN_grav(gravity + root motion)                  (1, d)
//   simulator  L post-LN layers over patch tokens; world heads attend to world-neighbour
//              patches and, jointly (one softmax), to body/wind/gravity tokens whose
//              messages go through the RET ψ(φ(R)(r+s)) and back with φ(R)ᵀ; mesh heads
//              attend to mesh-adjacent patches and the garment's attribute token.
//   decoder    patch branch and vertex branch (eq. 12–15) with the shared MLP, accelerations
//              rotated back, de-normalised with the velocity statistics, integrated.
//
// Output (root-relative, scene units, per frame):
//   vertex  (N, 9) = [x_{t+1}, v_{t+1}, a_{t+1}] of every garment vertex
//   patch   (P, 9) = the same for every patch centre
#include "autodiff/params.h"
#include "autodiff/tape.h"
#include "model/model_config.h"
#include "model/model_input.h"

#include <string>

namespace layersnet::model {

template <class T>
struct Predictions {
  ad::Var<T> vertex;  // (N, 9)
  ad::Var<T> patch;   // (P, 9)
};

// Implementation switches that do not change the function (tests compare both ways).
struct ForwardOptions {
  // Decoder with RET: φ(R) = W R Wᵀ has rank 3, so the first decoder layer's input
  // [rel, φ(R) e, φ(R) h] (12 + 2d) is replaced by [rel, R Wᵀe, R Wᵀh] (18) with the
  // weight [W1_rel | W1_e W | W1_h W] — exact, and the first layer costs 18/(12+2d) as much.
  bool factor_decoder = true;
  // RIA through the fused op (autodiff/ops_attention.h) instead of gather/segment composites.
  // Both compute eq. 7; they differ only in how eps enters the distance (fused:
  // sqrt(‖r−s‖² + eps²), composite: ‖r−s‖ + eps), i.e. by O(eps / ‖r−s‖) relative.
  bool fused_attention = true;
};

// One forward. `params` must come from register_params(config). With the tape recording,
// backward of anything computed from the predictions reaches every parameter that
// contributed; with NoRecord it is inference only.
template <class T>
Predictions<T> forward(ad::Tape<T>& tape, ad::ParamStore<T>& params, const ModelConfig& config,
                       const ModelInput<T>& input, const ForwardOptions& options = {});

// The RET map W (d, 3) named `name` as the forward uses it: the parameter itself with
// model.orthogonality = "penalty" (official; the loss adds ‖WWᵀ−I‖² + ‖WᵀW−I‖²), or, with
// "exact", Gram–Schmidt of its columns, so WᵀW = I holds exactly for any parameter value of
// rank 3 (φ(R) φ(R)ᵀ = W Wᵀ is then an exact rank-3 projector, the best eq. 9 allows with
// d > 3); the initial orthonormal parameter maps to itself.
template <class T>
ad::Var<T> rotation_map(ad::Tape<T>& tape, ad::ParamStore<T>& params, const ModelConfig& config,
                        const std::string& name);

}  // namespace layersnet::model
