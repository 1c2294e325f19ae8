#pragma once
// Every op's gradient check is declared with GRADCHECK_TEST(OpEnum, CaseName). The macro
// registers the op at static-initialisation time, so test_op_coverage.cpp can fail for an
// op in op_list.h that has no check; expect_gradcheck() then proves the check really put
// that op on the tape.
#include "autodiff/gradcheck.h"

#include <gtest/gtest.h>
#include <omp.h>

#include <random>
#include <set>

namespace layersnet::ad::testing {

inline std::set<OpKind>& ops_with_checks() {
  static std::set<OpKind> ops;
  return ops;
}

// Runs gradcheck and asserts: passed, finite, and `expected` was recorded on the tape.
inline GradcheckReport expect_gradcheck(OpKind expected, const GradcheckFn& f,
                                        const std::vector<GradcheckInput>& inputs,
                                        const GradcheckOptions& options = {}) {
  GradcheckReport rep = gradcheck(f, inputs, options);
  EXPECT_TRUE(rep.ops_seen.count(expected)) << op_name(expected) << " was not recorded on the tape";
  EXPECT_TRUE(rep.finite) << rep.failures;
  EXPECT_TRUE(rep.ok) << op_name(expected) << ":\n" << rep.failures;
  EXPECT_GT(rep.coords_checked, 0);
  return rep;
}

// Deterministic random matrix, entries uniform in [lo, hi].
inline RowMat<double> random_matrix(int64_t rows, int64_t cols, unsigned seed, double lo = -1, double hi = 1) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(lo, hi);
  RowMat<double> m(rows, cols);
  for (int64_t k = 0; k < m.size(); ++k) m.data()[k] = u(rng);
  return m;
}

// Runs f once with 1 thread and once with 2 threads; the outputs and gradients must be
// bit-identical (the reductions sum in a fixed order).
inline void expect_thread_count_invariant(const GradcheckFn& f, const std::vector<GradcheckInput>& inputs) {
  const int saved = omp_get_max_threads();
  GradcheckOptions opt;
  opt.max_coords = 1;  // only the analytic gradients matter here
  omp_set_num_threads(1);
  const GradcheckReport one = gradcheck(f, inputs, opt);
  omp_set_num_threads(2);
  const GradcheckReport two = gradcheck(f, inputs, opt);
  omp_set_num_threads(saved);
  EXPECT_TRUE((one.output.array() == two.output.array()).all());
  ASSERT_EQ(one.gradients.size(), two.gradients.size());
  for (std::size_t i = 0; i < one.gradients.size(); ++i)
    EXPECT_TRUE((one.gradients[i].array() == two.gradients[i].array()).all()) << "input " << i;
}

// Large inputs: a sample of coordinates is enough (each one costs two threaded forwards,
// which are slow when the machine is oversubscribed).
inline GradcheckOptions large_options() {
  GradcheckOptions opt;
  opt.max_coords = 12;
  return opt;
}

}  // namespace layersnet::ad::testing

#define GRADCHECK_TEST(Op, Case)                                                                \
  static const bool gradcheck_registered_##Op##_##Case =                                       \
      (::layersnet::ad::testing::ops_with_checks().insert(::layersnet::ad::OpKind::Op), true); \
  TEST(Gradcheck_##Op, Case)
