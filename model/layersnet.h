#pragma once
// The LayersNet forward pass (the paper's model, wired as the official code; decisions in
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

#include <Eigen/Core>
#include <cstdint>
#include <string>

namespace layersnet::model {

template <class T>
struct Predictions {
  ad::Var<T> vertex;  // (N, 9)
  ad::Var<T> patch;   // (P, 9)
};

// x_{t+1} of every garment vertex, the first three columns of Predictions::vertex: (N, 3),
// root-relative scene units.
template <class T>
Eigen::Matrix<T, Eigen::Dynamic, 3, Eigen::RowMajor> next_positions(const Predictions<T>& p) {
  return p.vertex.val().leftCols(3);
}

// Wall-clock split of one forward (ms, steady clock) and the work each stage did, for the
// cost benches (`layersnet bench scaling`, `bench scene`; model/README.md "Cost and scaling").
// forward() overwrites the whole struct. The stages run one after another, so
//   graph + encoder + attention + ffn + decoder <= total,
// and each "of which" field is part of the field above it. Timing never changes a value:
// the ops are synchronous (OpenMP inside), the clock is only read between them.
struct StageTimes {
  double graph_ms = 0;            // index lists of the attention graph (host loops over edges)
  double encoder_ms = 0;          // token encoders + receiver/sender streams (every token)
  double encoder_body_ms = 0;     //   of which: FFN_in of the U body tokens
  double attention_ms = 0;        // simulator attention, all layers: q/r/s projections, edges, output projection
  double attention_edges_ms = 0;  //   of which: per-edge work (RIA over world + inter + mesh rows, RET messages)
  double attention_inter_ms = 0;  //     of which: the inter edges' RET messages ψ (body, wind, gravity)
  double ffn_ms = 0;              // simulator FFN, LayerNorms and memory projections, all layers
  double decoder_ms = 0;          // decoder (patch and vertex branches) and integration
  double total_ms = 0;            // the whole forward() call
  // Work of the same forward (rows per layer), for per-row cost models.
  int64_t patch_rows = 0;      // P
  int64_t token_rows = 0;      // P + A + T, T = U body + [wind] + gravity tokens
  int64_t body_tokens = 0;     // U
  int64_t ext_tokens = 0;      // wind (0/1) + gravity (1)
  int64_t world_rows = 0;      // world edges (patch -> patch)
  int64_t inter_rows = 0;      // inter edges (patch -> body/wind/gravity token), incl. body_rows
  int64_t body_rows = 0;       // inter edges to body tokens
  int64_t mesh_rows = 0;       // mesh edges incl. each patch's attribute token
  int64_t vertex_rows = 0;     // N
  int64_t candidate_rows = 0;  // decoder vertex-branch rows (candidate patches of all vertices)
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
  // Factor on the decoder's outputs, i.e. on the correction of the velocity base (eval.correction_scale);
  // 0 skips the network: the prediction is the base alone.
  double correction_scale = 1.0;
  // When set, forward() fills it (see StageTimes); null: the clock is never read.
  StageTimes* times = nullptr;
};

// One forward. `params` must come from register_params(config). With the tape recording,
// backward of anything computed from the predictions reaches every parameter that
// contributed; with NoRecord it is inference only.
// garment_state (N, 12), optional: the state [x̃_t, v_t, x̃_{t−1}, v_{t−1}] that `input` was
// built from, as a tape variable (e.g. made from the previous step's predictions). Every value
// still comes from `input`; the backward also reaches garment_state through what the input
// derives linearly from it: the patch means and their normalised embedding input, the decoder's
// relative states and the integration bases. The neighbourhoods, nearest body vertices and
// vertex_local features count as constants. Training through self-fed steps uses it.
template <class T>
Predictions<T> forward(ad::Tape<T>& tape, ad::ParamStore<T>& params, const ModelConfig& config,
                       const ModelInput<T>& input, const ForwardOptions& options = {},
                       const ad::Var<T>& garment_state = {});

// The RET map W (d, 3) named `name` as the forward uses it: the parameter itself with
// model.orthogonality = "penalty" (official; the loss adds ‖WWᵀ−I‖² + ‖WᵀW−I‖²), or, with
// "exact", Gram–Schmidt of its columns, so WᵀW = I holds exactly for any parameter value of
// rank 3 (φ(R) φ(R)ᵀ = W Wᵀ is then an exact rank-3 projector, the best eq. 9 allows with
// d > 3); the initial orthonormal parameter maps to itself.
template <class T>
ad::Var<T> rotation_map(ad::Tape<T>& tape, ad::ParamStore<T>& params, const ModelConfig& config,
                        const std::string& name);

}  // namespace layersnet::model
