// Overfit, small bound: the model overfits one sample with Adam.
#include "autodiff/optim.h"
#include "losses/losses.h"
#include "model/layersnet.h"
#include "model/params_layout.h"
#include "model_test_util.h"

#include <gtest/gtest.h>

#include <omp.h>

#include <iostream>

namespace layersnet::model {
namespace {

TEST(ModelOverfit, OneSampleLossDropsTenfold) {
  // Tiny tensors: one thread avoids fork/join waits on a busy machine (results do not
  // depend on the thread count).
  const int threads = omp_get_max_threads();
  omp_set_num_threads(1);
  const auto c = testing::tiny_config();
  const auto w = testing::window(dataset::make_synthetic_sequence(testing::tiny_scene()), c);
  const auto& in = w.input;
  const auto& target = w.target;
  ad::ParamStore<float> ps;
  register_params(ps, c);
  init_params(ps, c, 1);
  ad::Adam<float> adam(ps, {.lr = 1e-3});
  ad::Tape<float> tape;
  LossConfig lc;
  // Data terms only: the orthogonality penalty sits at its floor Σ(d − 3) from the start.
  auto data_loss = [](const losses::LossTerms<float>& t) {
    return t.vertex + t.patch + t.normal + 1.3 * t.collision_body + 0.1 * t.collision_layer;
  };
  double first = 0, last = 0;
  for (int step = 0; step < 400; ++step) {
    tape.reset();
    ps.zero_grads();
    const auto pred = forward(tape, ps, c, in);
    const auto t = losses::compute_losses(tape, ps, c, lc, target, pred);
    tape.backward(t.total);
    adam.step();
    if (step == 0) first = data_loss(t);
    last = data_loss(t);
  }
  std::cout << "overfit: data loss " << first << " -> " << last << " (" << first / last << "x) in 400 steps\n";
  omp_set_num_threads(threads);
  EXPECT_LT(last, first / 10);
}

}  // namespace
}  // namespace layersnet::model
