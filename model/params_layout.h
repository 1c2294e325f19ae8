#pragma once
// The LayersNet parameters in one ParamStore, with dotted names, and their initialisation.
//
// Sizes from ModelConfig: d = width, H = heads (H/2 world + H/2 mesh heads), hd = d / H,
// groups = H / 2 (each group is one world head; its RET map W_g is (hd, 3)), L = layers,
// f = ffn_width, w = decoder_width, decoder input 12 + 2d. Linear weights in torch layout
// (out, in), biases and LayerNorm parameters (1, C).
//
//   embed.{input (12), attr (5), wind (10), gravity (18)}.{0,1}.{weight,bias}   FFN → d → d, ReLU after both
//   embed.{receiver,sender}.{0,1}.{weight,bias}                                d → d → d, ReLU after both
//   embed.{receiver_norm,sender_norm,particle_norm}.{weight,bias}
//   encoder.layers.{l}.attn.{receiver_weight,sender_weight,memory_weight,q_proj}.weight  (d, d), no bias
//   encoder.layers.{l}.attn.proj.{weight,bias}, .n_weight, .n_bias
//   encoder.layers.{l}.attn.{r_proj,s_proj}.{weight,bias}        all layers but the last
//   encoder.layers.{l}.attn.rot_mapping.{g}.weight (hd, 3)         only with RET
//   encoder.layers.{l}.attn.rs_mlp.{g}.{weight (hd, hd), bias}     the interaction MLP ψ
//   encoder.layers.{l}.ffn.{0 (f, d), 1 (d, f)}.{weight,bias}
//   encoder.layers.{l}.norms.{0,1}.{weight,bias}
//   encoder.layers.{l}.res_norms.{0,1}.{weight,bias}               all layers but the last
//   decoder.rot_mapping.weight (d, 3)                               only with RET
//   decoder.proj.{0 (w, 12+2d), 1 (w, w), 2 (3, w)}.{weight,bias}
//
// The official model also holds the last layer's r_proj, s_proj and res_norms, whose
// outputs are never used (dead code, no gradient); we do not register them
// (official_parameter_count() counts them, for comparison with the reference ≈ 1.02 M).
#include "autodiff/params.h"
#include "model/model_config.h"

#include <cstdint>
#include <string>

namespace layersnet::model {

// Sizes derived from a ModelConfig (checked: width divisible by heads, heads even).
struct ModelDims {
  int d = 0, heads = 0, head_dim = 0, groups = 0, layers = 0, ffn = 0, dec_width = 0, dec_in = 0;
  static constexpr int kStateDim = 12, kAttrDim = 5, kWindDim = 10, kGravityDim = 18;
};
ModelDims model_dims(const ModelConfig& config);

// Registers every tensor and finalises the store (which must be empty).
template <class T>
void register_params(ad::ParamStore<T>& params, const ModelConfig& config);

// torch defaults: Linear weight and bias U(-1/√fan_in, 1/√fan_in); LayerNorm and the
// attention's per-channel affine 1 / 0; every RET map W orthonormal columns (QR of a
// Gaussian, as nn.init.orthogonal_). Deterministic for a seed.
template <class T>
void init_params(ad::ParamStore<T>& params, const ModelConfig& config, uint64_t seed);

// Names of the RET maps W (for the orthogonality penalty); empty without RET.
std::vector<std::string> rotation_map_names(const ModelConfig& config);

// The smallest value the orthogonality penalty Σ_W ‖W Wᵀ − I‖² + ‖Wᵀ W − I‖² can take: Σ_W |d_W − c_W|
// for W (d_W, c_W), since the larger of W Wᵀ, Wᵀ W has |d_W − c_W| zero eigenvalues (rank
// min(d_W, c_W)); orthonormal columns, the initialisation, reach it. A constant the optimiser
// cannot remove, so logs show the excess over it. 0 without a penalty (no RET, or
// model.orthogonality = "exact").
double orthogonality_floor(const ModelConfig& config);

// Parameter count of the official layout with these sizes (incl. the dead last-layer
// tensors; official sizes: 1,018,719).
int64_t official_parameter_count(const ModelConfig& config);

// One line per tensor (name, shape) and the totals.
template <class T>
std::string describe_params(const ad::ParamStore<T>& params, const ModelConfig& config);

}  // namespace layersnet::model
