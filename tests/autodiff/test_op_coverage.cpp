// Fails for every op in autodiff/op_list*.h that has no GRADCHECK_TEST.
#include "gradcheck_registry.h"

namespace layersnet::ad::testing {

TEST(OpCoverage, EveryOpHasAGradientCheck) {
  ASSERT_GT(kOpCount, 0);
  for (int32_t k = 0; k < kOpCount; ++k) {
    const auto op = static_cast<OpKind>(k);
    EXPECT_TRUE(ops_with_checks().count(op)) << "op " << op_name(op) << " has no GRADCHECK_TEST";
  }
}

}  // namespace layersnet::ad::testing
