// Adam over the ParamStore: it optimises, it is deterministic, it resumes exactly.
#include "autodiff/ops_dense.h"
#include "autodiff/optim.h"
#include "gradcheck_registry.h"

#include <cmath>
#include <random>

namespace layersnet::ad::testing {

namespace {

// y = x W_trueᵀ + b_true + noise: a least-squares problem for a (2, 5) linear layer.
struct LeastSquares {
  RowMat<float> x, y;
  explicit LeastSquares(unsigned seed) {
    const RowMat<double> xd = random_matrix(64, 5, seed), w = random_matrix(2, 5, seed + 1, -2, 2);
    const RowMat<double> b = random_matrix(1, 2, seed + 2), noise = random_matrix(64, 2, seed + 3, -0.01, 0.01);
    x = xd.cast<float>();
    y = (((xd * w.transpose()).rowwise() + b.row(0)) + noise).cast<float>();
  }
};

struct Model {
  ParamStore<float> params;
  int w = 0, b = 0;
  explicit Model(unsigned seed) {
    w = params.add("fit.weight", 2, 5);
    b = params.add("fit.bias", 1, 2);
    params.finalize();
    std::mt19937 rng(seed);
    std::normal_distribution<float> normal(0.0f, 0.1f);
    for (float& v : params.values()) v = normal(rng);
  }
};

float loss_and_grad(Tape<float>& tape, Model& m, const LeastSquares& data) {
  tape.reset();
  m.params.zero_grads();
  const Var<float> x = tape.constant(data.x.data(), data.x.rows(), data.x.cols());
  const Var<float> y = tape.constant(data.y.data(), data.y.rows(), data.y.cols());
  const Var<float> loss = mean_all(tape, squared_error(tape, linear(tape, x, m.params.var(m.w), m.params.var(m.b)), y));
  tape.backward(loss);
  return loss.scalar();
}

std::vector<float> train(unsigned seed, int steps, float* first_loss = nullptr, float* last_loss = nullptr) {
  const LeastSquares data(100);
  Model m(seed);
  Tape<float> tape;
  AdamOptions opt;
  opt.lr = 0.02;
  Adam<float> adam(m.params, opt);
  for (int s = 0; s < steps; ++s) {
    const float loss = loss_and_grad(tape, m, data);
    if (s == 0 && first_loss) *first_loss = loss;
    if (last_loss) *last_loss = loss;
    adam.step();
  }
  EXPECT_EQ(adam.step_count(), steps);
  return {m.params.values().begin(), m.params.values().end()};
}

}  // namespace

TEST(Adam, LeastSquaresLossFallsTenfold) {
  float first = 0, last = 0;
  train(7, 300, &first, &last);
  EXPECT_TRUE(std::isfinite(last));
  EXPECT_LT(last, first / 10) << "first " << first << " last " << last;
}

TEST(Adam, SameSeedGivesBitIdenticalParameters) {
  const auto a = train(7, 50), b = train(7, 50), c = train(8, 50);
  EXPECT_EQ(a, b);
  EXPECT_NE(a, c);
}

TEST(Adam, FirstStepIsLrTimesSignOfGradient) {
  // t = 1: m̂ = g, v̂ = g², so the update is lr * g / (|g| + eps).
  ParamStore<double> params;
  params.add("p", 1, 4);
  params.finalize();
  const double g[4] = {0.5, -2.0, 1e-3, 0.0};
  for (int k = 0; k < 4; ++k) params.values()[k] = 1.0, params.grads()[k] = g[k];
  AdamOptions opt;
  opt.lr = 0.1;
  Adam<double> adam(params, opt);
  adam.step();
  for (int k = 0; k < 4; ++k)
    EXPECT_NEAR(params.values()[k], 1.0 - 0.1 * g[k] / (std::abs(g[k]) + 1e-8), 1e-15) << k;
  EXPECT_NEAR(params.moment1()[1], 0.1 * -2.0, 1e-15);
  EXPECT_NEAR(params.moment2()[1], 0.001 * 4.0, 1e-15);
}

TEST(Adam, ResumeFromStepCountAndMomentsIsExact) {
  // 10 steps, copy values + moments + t into a fresh optimizer, 10 more == 20 straight.
  const LeastSquares data(100);  // as train()
  const std::vector<float> straight = train(9, 20);
  Model m1(9);
  Tape<float> tape;
  AdamOptions opt;
  opt.lr = 0.02;
  {
    Adam<float> adam(m1.params, opt);
    for (int s = 0; s < 10; ++s) loss_and_grad(tape, m1, data), adam.step();
  }
  Model m2(1234);  // different init, overwritten by the "checkpoint"
  std::copy(m1.params.values().begin(), m1.params.values().end(), m2.params.values().begin());
  std::copy(m1.params.moment1().begin(), m1.params.moment1().end(), m2.params.moment1().begin());
  std::copy(m1.params.moment2().begin(), m1.params.moment2().end(), m2.params.moment2().begin());
  Adam<float> resumed(m2.params, opt);
  resumed.set_step_count(10);
  for (int s = 0; s < 10; ++s) loss_and_grad(tape, m2, data), resumed.step();
  EXPECT_EQ(std::vector<float>(m2.params.values().begin(), m2.params.values().end()), straight);
}

TEST(Adam, GradNormAndBadOptions) {
  ParamStore<float> params;
  params.add("a", 2, 2);
  params.add("b", 1, 1);
  params.finalize();
  std::fill(params.grads().begin(), params.grads().end(), 0.0f);
  params.grads()[0] = 3.0f;
  params.grads()[params.entries()[1].offset] = 4.0f;
  EXPECT_DOUBLE_EQ(grad_norm(params), 5.0);
  AdamOptions bad;
  bad.beta2 = 1.0;
  EXPECT_THROW(Adam<float>(params, bad), CheckError);
}

}  // namespace layersnet::ad::testing
