#pragma once
// Preconditioned conjugate gradients in double precision, for the physics step's Newton systems
// (losses/physics_step.cpp) and the block solve on the tape (autodiff/ops_solve.h).
#include <cstddef>
#include <vector>

namespace layersnet::ad {

// Solves A x = b from x = 0. multiply(p, y) sets y = A p; precondition(r, z) sets z ≈ A⁻¹ r.
// Stops after `iterations`, when rᵀz falls to stop_ratio times its start (stop_ratio = tol² for
// a relative residual tol in the preconditioned norm), or where A is not positive along the
// search direction (the iterate so far is kept). Sequential: the result does not depend on the
// thread count.
template <class Multiply, class Precondition>
std::vector<double> conjugate_gradients(std::vector<double> r, Multiply&& multiply, Precondition&& precondition,
                                        int iterations, double stop_ratio) {
  const std::size_t n = r.size();
  std::vector<double> x(n, 0.0), z(n), d(n), q(n);
  auto dot = [](const std::vector<double>& a, const std::vector<double>& b) {
    double s = 0;
    for (std::size_t k = 0; k < a.size(); ++k) s += a[k] * b[k];
    return s;
  };
  precondition(r, z);
  d = z;
  double rz = dot(r, z);
  const double stop = stop_ratio * rz;
  for (int it = 0; it < iterations && rz > stop && rz > 0; ++it) {
    multiply(d, q);
    const double dq = dot(d, q);
    if (!(dq > 0)) break;
    const double alpha = rz / dq;
    for (std::size_t k = 0; k < n; ++k) x[k] += alpha * d[k], r[k] -= alpha * q[k];
    precondition(r, z);
    const double rz_next = dot(r, z);
    const double beta = rz_next / rz;
    rz = rz_next;
    for (std::size_t k = 0; k < n; ++k) d[k] = z[k] + beta * d[k];
  }
  return x;
}

}  // namespace layersnet::ad
