#include "model/params_layout.h"

#include "autodiff/check.h"
#include "model/model_input.h"

#include <Eigen/QR>

#include <cmath>
#include <cstdlib>
#include <random>
#include <utility>
#include <sstream>

namespace layersnet::model {
namespace {

// Adds an MLP "prefix.{i}.{weight,bias}" with the given widths.
template <class T>
void add_mlp(ad::ParamStore<T>& ps, const std::string& prefix, std::initializer_list<int> widths, bool bias = true) {
  std::vector<int> w(widths);
  for (std::size_t i = 0; i + 1 < w.size(); ++i) {
    ps.add(prefix + "." + std::to_string(i) + ".weight", w[i + 1], w[i]);
    if (bias) ps.add(prefix + "." + std::to_string(i) + ".bias", 1, w[i + 1]);
  }
}

template <class T>
void add_norm(ad::ParamStore<T>& ps, const std::string& prefix, int d) {
  ps.add(prefix + ".weight", 1, d);
  ps.add(prefix + ".bias", 1, d);
}

bool ends_with(const std::string& s, const std::string& suffix) {
  return s.size() >= suffix.size() && s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
}

}  // namespace

ModelDims model_dims(const ModelConfig& c) {
  LAYERSNET_CHECK(c.width > 0 && c.heads > 0 && c.heads % 2 == 0 && c.width % c.heads == 0,
                  "model.width = " << c.width << ", model.heads = " << c.heads
                                   << ": heads must be even (half world, half mesh) and divide width");
  LAYERSNET_CHECK(c.layers >= 1 && c.ffn_width > 0 && c.decoder_width > 0,
                  "model.layers, ffn_width and decoder_width must be positive");
  LAYERSNET_CHECK(c.attention == "ria" || c.attention == "tie",
                  "model.attention = '" << c.attention << "': use \"ria\" or \"tie\"");
  LAYERSNET_CHECK(c.orthogonality == "penalty" || c.orthogonality == "exact",
                  "model.orthogonality = '" << c.orthogonality << "': use \"penalty\" or \"exact\"");
  LAYERSNET_CHECK(!c.rotation_equivalent || (c.decoder_ret_channels >= 1 && 3 * c.decoder_ret_channels <= c.width),
                  "model.decoder_ret_channels = " << c.decoder_ret_channels << " with model.width = " << c.width
                                                  << ": need 1 <= k and 3k <= width");
  ModelDims m;
  m.d = c.width, m.heads = c.heads, m.head_dim = c.width / c.heads, m.groups = c.heads / 2;
  m.layers = c.layers, m.ffn = c.ffn_width, m.dec_width = c.decoder_width, m.dec_in = 12 + 2 * c.width;
  return m;
}

template <class T>
void register_params(ad::ParamStore<T>& ps, const ModelConfig& c) {
  LAYERSNET_CHECK(ps.entries().empty() && !ps.finalized(), "register_params needs an empty ParamStore");
  const ModelDims m = model_dims(c);
  const int d = m.d;
  add_mlp(ps, "embed.input", {ModelDims::kStateDim, d, d});
  add_mlp(ps, "embed.attr", {ModelDims::kAttrDim, d, d});
  add_mlp(ps, "embed.wind", {ModelDims::kWindDim, d, d});
  add_mlp(ps, "embed.gravity", {ModelDims::kGravityDim, d, d});
  add_mlp(ps, "embed.receiver", {d, d, d});
  add_mlp(ps, "embed.sender", {d, d, d});
  add_norm(ps, "embed.receiver_norm", d);
  add_norm(ps, "embed.sender_norm", d);
  add_norm(ps, "embed.particle_norm", d);
  for (int l = 0; l < m.layers; ++l) {
    const std::string p = "encoder.layers." + std::to_string(l) + ".";
    const bool last = l == m.layers - 1;
    for (const char* w : {"receiver_weight", "sender_weight", "memory_weight", "q_proj"})
      ps.add(p + "attn." + w + ".weight", d, d);
    ps.add(p + "attn.proj.weight", d, d);
    ps.add(p + "attn.proj.bias", 1, d);
    if (!last) {
      for (const char* w : {"r_proj", "s_proj"}) {
        ps.add(p + "attn." + w + ".weight", d, d);
        ps.add(p + "attn." + w + ".bias", 1, d);
      }
    }
    ps.add(p + "attn.n_weight", 1, d);
    ps.add(p + "attn.n_bias", 1, d);
    for (int g = 0; g < m.groups; ++g) {
      if (c.rotation_equivalent) ps.add(p + "attn.rot_mapping." + std::to_string(g) + ".weight", m.head_dim, 3);
      ps.add(p + "attn.rs_mlp." + std::to_string(g) + ".weight", m.head_dim, m.head_dim);
      ps.add(p + "attn.rs_mlp." + std::to_string(g) + ".bias", 1, m.head_dim);
    }
    add_mlp(ps, p + "ffn", {d, m.ffn, d});
    add_norm(ps, p + "norms.0", d);
    add_norm(ps, p + "norms.1", d);
    if (!last) {
      add_norm(ps, p + "res_norms.0", d);
      add_norm(ps, p + "res_norms.1", d);
    }
  }
  if (c.rotation_equivalent) ps.add("decoder.rot_mapping.weight", d, 3 * c.decoder_ret_channels);
  add_mlp(ps, "decoder.proj", {m.dec_in, m.dec_width, m.dec_width, 3});
  // Registered last so that switching it on leaves every other initial value unchanged.
  if (c.vertex_local_features) ps.add("decoder.local.weight", m.dec_width, kVertexLocalDim);
  if (c.patch_base_input) ps.add("embed.base.weight", m.d, 3);
  if (c.wind_force_input) {
    ps.add("embed.wind_force.weight", m.d, 3);
    ps.add("decoder.wind.weight", m.dec_width, 3);
  }
  if (c.vertex_base_input) ps.add("decoder.base.weight", m.dec_width, 6);
  ps.finalize();
}

std::vector<std::string> rotation_map_names(const ModelConfig& c) {
  std::vector<std::string> names;
  if (!c.rotation_equivalent) return names;
  const ModelDims m = model_dims(c);
  for (int l = 0; l < m.layers; ++l)
    for (int g = 0; g < m.groups; ++g)
      names.push_back("encoder.layers." + std::to_string(l) + ".attn.rot_mapping." + std::to_string(g) + ".weight");
  names.push_back("decoder.rot_mapping.weight");
  return names;
}

double orthogonality_floor(const ModelConfig& c) {
  if (!c.rotation_equivalent || c.orthogonality == "exact") return 0.0;
  const ModelDims m = model_dims(c);
  // The shapes register_params gives the maps: (hd, 3) per layer and group, decoder (d, 3k).
  return static_cast<double>(m.layers * m.groups * std::abs(m.head_dim - 3) + std::abs(m.d - 3 * c.decoder_ret_channels));
}

template <class T>
void init_params(ad::ParamStore<T>& ps, const ModelConfig& c, uint64_t seed) {
  std::mt19937_64 rng(seed);
  const auto& entries = ps.entries();
  // fan_in of a bias = the in-width of its weight (registered just before it).
  for (std::size_t i = 0; i < entries.size(); ++i) {
    const ad::ParamEntry& e = entries[i];
    auto v = ps.value(static_cast<int>(i));
    const bool is_norm = e.name.find("norm") != std::string::npos || ends_with(e.name, "n_weight") ||
                         ends_with(e.name, "n_bias");
    if (is_norm) {
      const bool one = ends_with(e.name, ".weight") || ends_with(e.name, "n_weight");
      std::fill(v.begin(), v.end(), one ? T(1) : T(0));
    } else if (e.name.find("rot_mapping") != std::string::npos) {
      std::normal_distribution<double> normal(0.0, 1.0);
      Eigen::MatrixXd a(e.rows, e.cols);
      for (int64_t r = 0; r < e.rows; ++r)
        for (int64_t k = 0; k < e.cols; ++k) a(r, k) = normal(rng);
      Eigen::HouseholderQR<Eigen::MatrixXd> qr(a);
      Eigen::MatrixXd q = qr.householderQ() * Eigen::MatrixXd::Identity(e.rows, e.cols);
      const Eigen::MatrixXd rr = qr.matrixQR();
      for (int64_t k = 0; k < e.cols; ++k)
        if (rr(k, k) < 0) q.col(k) *= -1;  // sign convention of torch's orthogonal_
      for (int64_t r = 0; r < e.rows; ++r)
        for (int64_t k = 0; k < e.cols; ++k) v[r * e.cols + k] = static_cast<T>(q(r, k));
    } else {
      const int64_t fan_in = ends_with(e.name, ".bias") ? entries[i - 1].cols : e.cols;
      const double bound = 1.0 / std::sqrt(static_cast<double>(fan_in));
      std::uniform_real_distribution<double> uni(-bound, bound);
      for (auto& x : v) x = static_cast<T>(uni(rng));
    }
  }
  // With the body-carried velocity base a zero output is the skinning step: start there, the
  // other weights drawn as before (the same draws as the inertial model of the same seed).
  // The base inputs enter at zero: switched on, the model starts as the one without them.
  for (const auto& [on, name] : {std::pair{c.patch_base_input, "embed.base.weight"},
                                 std::pair{c.vertex_base_input, "decoder.base.weight"}})
    if (on) {
      auto v = ps.value(ps.index_of(name));
      std::fill(v.begin(), v.end(), T(0));
    }
  if (c.wind_force_input)  // likewise
    for (const char* name : {"embed.wind_force.weight", "decoder.wind.weight"}) {
      auto v = ps.value(ps.index_of(name));
      std::fill(v.begin(), v.end(), T(0));
    }
  if (c.velocity_base != "inertia")
    for (std::size_t i = 0; i < entries.size(); ++i)
      if (entries[i].name.rfind("decoder.proj.2.", 0) == 0) {
        auto v = ps.value(static_cast<int>(i));
        std::fill(v.begin(), v.end(), T(0));
      }
}

int64_t official_parameter_count(const ModelConfig& c) {
  const ModelDims m = model_dims(c);
  const int64_t d = m.d;
  auto mlp2 = [&](int64_t in) { return in * d + d + d * d + d; };
  int64_t embed = mlp2(12) + mlp2(5) + mlp2(22) + mlp2(6) + 2 * mlp2(d) + 3 * 2 * d + 3 * d /* decoder W */;
  int64_t layer = 4 * d * d + 3 * (d * d + d) + 2 * d + m.groups * (m.head_dim * 3 + m.head_dim * m.head_dim + m.head_dim) +
                  (d * m.ffn + m.ffn + m.ffn * d + d) + 4 * 2 * d;
  int64_t w = m.dec_width;
  int64_t head = m.dec_in * w + w + w * w + w + w * 3 + 3;
  return embed + m.layers * layer + head;
}

template <class T>
std::string describe_params(const ad::ParamStore<T>& ps, const ModelConfig& c) {
  std::ostringstream s;
  for (const auto& e : ps.entries()) s << e.name << " (" << e.rows << ", " << e.cols << ")\n";
  int64_t total = 0;
  for (const auto& e : ps.entries()) total += e.size();
  s << "parameters: " << total << " in " << ps.entries().size() << " tensors (official layout with these sizes: "
    << official_parameter_count(c) << ", incl. the last layer's unused r_proj/s_proj/res_norms)\n";
  return s.str();
}

template void register_params(ad::ParamStore<float>&, const ModelConfig&);
template void register_params(ad::ParamStore<double>&, const ModelConfig&);
template void init_params(ad::ParamStore<float>&, const ModelConfig&, uint64_t);
template void init_params(ad::ParamStore<double>&, const ModelConfig&, uint64_t);
template std::string describe_params(const ad::ParamStore<float>&, const ModelConfig&);
template std::string describe_params(const ad::ParamStore<double>&, const ModelConfig&);

}  // namespace layersnet::model
