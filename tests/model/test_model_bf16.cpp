// Whole model with bfloat16 linear products (inference only, autodiff/bf16_gemm.h): the
// predictions stay within a tolerance of the float forward, and really differ from it.
#include "autodiff/bf16_gemm.h"
#include "model/layersnet.h"
#include "model/params_layout.h"
#include "model_test_util.h"

#include <gtest/gtest.h>

#include <cmath>
#include <iostream>
#include <vector>

namespace layersnet::model {
namespace {

// max |a_bf16 − a_float| / max |a_float| over the predicted accelerations (columns 6..8 of
// the vertex and patch predictions: the network's output before integration; positions are
// mostly x_t and would hide the difference).
double bf16_relative_error(const ModelConfig& c, unsigned seed) {
  const auto in = testing::window(dataset::make_synthetic_sequence(testing::tiny_scene()), c).input;
  ad::ParamStore<float> ps;
  register_params(ps, c);
  init_params(ps, c, seed);
  ad::Tape<float> tape;
  ad::NoRecord<float> off(tape);
  std::vector<float> out[2];
  for (int k = 0; k < 2; ++k) {
    tape.reset();
    tape.set_matmul_precision(k == 0 ? ad::MatmulPrecision::kFloat32 : ad::MatmulPrecision::kBFloat16);
    const auto pred = forward(tape, ps, c, in);
    out[k].clear();
    for (const auto& y : {pred.vertex, pred.patch})
      for (int64_t i = 0; i < y.rows; ++i) out[k].insert(out[k].end(), y.value + 9 * i + 6, y.value + 9 * i + 9);
  }
  double ymax = 0, dmax = 0;
  for (std::size_t i = 0; i < out[0].size(); ++i) {
    EXPECT_TRUE(std::isfinite(out[1][i]));
    ymax = std::max(ymax, double(std::abs(out[0][i])));
    dmax = std::max(dmax, double(std::abs(out[1][i] - out[0][i])));
  }
  return dmax / ymax;
}

TEST(ModelBf16, ForwardStaysCloseToFloat) {
  ad::bf16_clear_weight_cache();
  // The tiny configuration (width 16: every feature layer qualifies) and the official sizes.
  ModelConfig official;
  for (const ModelConfig& c : {testing::tiny_config(), official}) {
    const double err = bf16_relative_error(c, 3);
    std::cout << "width " << c.width << ": bf16 forward, accelerations max |diff| / max |a| = " << err << " ("
              << ad::bf16_kernel_name() << ")\n";
    EXPECT_GT(err, 1e-5);  // bf16 products were used (the same float code would agree exactly)
    EXPECT_LT(err, 0.01);  // observed ~9e-4 (width 16) and ~6e-4 (official sizes)
  }
  EXPECT_GT(ad::bf16_weight_cache_stats().packs, 0);
}

}  // namespace
}  // namespace layersnet::model
