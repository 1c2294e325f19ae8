// Gradient checks of the dense ops (autodiff/ops_dense.h).
#include "autodiff/ops_dense.h"
#include "gradcheck_registry.h"

namespace layersnet::ad::testing {

GRADCHECK_TEST(Add, SameShapeAndEveryBroadcast) {
  const auto f = [](Tape<double>& t, const std::vector<Var<double>>& v) {
    Var<double> y = add(t, v[0], v[1]);  // (N, C) + (N, C)
    y = add(t, y, v[2]);                 // + (1, C)
    y = add(t, y, v[3]);                 // + (N, 1)
    return add(t, y, v[4]);              // + (1, 1)
  };
  expect_gradcheck(OpKind::Add, f,
                   {{random_matrix(5, 4, 1)}, {random_matrix(5, 4, 2)}, {random_matrix(1, 4, 3)},
                    {random_matrix(5, 1, 4)}, {random_matrix(1, 1, 5)}});
}

GRADCHECK_TEST(Add, OneRowAndConstantOperand) {
  const auto f = [](Tape<double>& t, const std::vector<Var<double>>& v) { return add(t, v[0], v[1]); };
  expect_gradcheck(OpKind::Add, f, {{random_matrix(1, 3, 6)}, {random_matrix(1, 3, 7), false}});
}

TEST(Gradcheck, HarnessCatchesAWrongGradient) {
  // The harness must be able to fail: compare against a function whose forward is not
  // what its recorded backward says (add's backward, but the forward doubles a).
  const auto f = [](Tape<double>& t, const std::vector<Var<double>>& v) {
    Var<double> y = add(t, v[0], v[1]);
    y.val() += v[0].val();  // forward changed behind the tape's back
    return y;
  };
  const GradcheckReport rep = gradcheck(f, {{random_matrix(3, 3, 8)}, {random_matrix(3, 3, 9)}});
  EXPECT_FALSE(rep.ok);
}

}  // namespace layersnet::ad::testing
