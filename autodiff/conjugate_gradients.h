#pragma once
// Preconditioned conjugate gradients in double precision over rows of 3 unknowns, for the
// physics step's Newton systems (losses/physics_step.cpp) and the block solve on the tape
// (autodiff/ops_solve.h), on one thread or several.
#include <omp.h>

#include <algorithm>
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <thread>
#include <vector>

namespace layersnet::ad {

// The threads of one parallel region meet here without sleeping. Between the conjugate
// gradients' steps a wait lasts microseconds, less than waking a thread that sleeps in OpenMP's
// own barrier (layersnet runs with OMP_WAIT_POLICY=PASSIVE); a waiter that has spun for longer
// yields its core, so a partner that lost its core gets it back soon. Every caller passes the
// same team size: the threads OpenMP gave the region, which may be fewer than it was asked for.
class SpinBarrier {
 public:
  void wait(int team) {
    const uint32_t generation = generation_.load(std::memory_order_acquire);
    if (arrived_.fetch_add(1, std::memory_order_acq_rel) + 1 == team) {
      arrived_.store(0, std::memory_order_relaxed);
      generation_.fetch_add(1, std::memory_order_release);
      return;
    }
    for (int spins = 0; generation_.load(std::memory_order_acquire) == generation; ++spins) {
      if (spins < kSpinsBeforeYield) {
#if defined(__x86_64__) || defined(__i386__)
        __builtin_ia32_pause();
#endif
      } else {
        std::this_thread::yield();
      }
    }
  }

 private:
  static constexpr int kSpinsBeforeYield = 2000;
  std::atomic<int> arrived_{0};
  std::atomic<uint32_t> generation_{0};
};

// Rows per chunk of the dot products' partial sums: chunks are summed in order, so the result is
// the same for any thread count.
inline constexpr int64_t kConjugateGradientChunkRows = 256;

// Solves A x = b from x = 0, b = r (3 · rows). multiply(p, y, r0, r1) sets rows [r0, r1) of
// y = A p (reading any row of p); precondition(r, z, r0, r1) sets those rows of z ≈ A⁻¹ r (each
// row from the same row of r). Stops after `iterations`, when rᵀz falls to stop_ratio times its
// start (stop_ratio = tol² for a relative residual tol in the preconditioned norm), or where A is
// not positive along the search direction (the iterate so far is kept). `threads` > 1 splits the
// rows among that many threads of one parallel region, meeting three times an iteration.
template <class Multiply, class Precondition>
std::vector<double> conjugate_gradients(std::vector<double> r, Multiply&& multiply, Precondition&& precondition,
                                        int iterations, double stop_ratio, int threads = 1) {
  const std::size_t n = r.size();
  const int64_t rows = static_cast<int64_t>(n / 3);
  const int64_t chunks = (rows + kConjugateGradientChunkRows - 1) / kConjugateGradientChunkRows;
  std::vector<double> x(n, 0.0), z(n), d(n), q(n);
  // Per-chunk partial sums of dᵀq and of rᵀz: two arrays, so a thread can write the next sum
  // while another still reads the last.
  std::vector<double> part_dq(static_cast<std::size_t>(chunks)), part_rz(static_cast<std::size_t>(chunks));
  auto total = [&](const std::vector<double>& part) {
    double s = 0;
    for (double v : part) s += v;
    return s;
  };
  auto chunk_dot = [&](const std::vector<double>& a, const std::vector<double>& b, int64_t c) {
    double s = 0;
    const std::size_t end = 3 * static_cast<std::size_t>(std::min(rows, (c + 1) * kConjugateGradientChunkRows));
    for (std::size_t k = 3 * static_cast<std::size_t>(c * kConjugateGradientChunkRows); k < end; ++k) s += a[k] * b[k];
    return s;
  };
  threads = static_cast<int>(std::clamp<int64_t>(threads, 1, std::max<int64_t>(chunks, 1)));
  SpinBarrier barrier;
#pragma omp parallel num_threads(threads) if (threads > 1)
  {
    const int64_t team = omp_get_num_threads(), me = omp_get_thread_num();
    const int64_t c0 = chunks * me / team, c1 = chunks * (me + 1) / team;  // this thread's chunks
    const int64_t r0 = c0 * kConjugateGradientChunkRows, r1 = std::min(rows, c1 * kConjugateGradientChunkRows);
    auto sync = [&] {
      if (team > 1) barrier.wait(static_cast<int>(team));
    };
    precondition(r, z, r0, r1);
    for (int64_t k = 3 * r0; k < 3 * r1; ++k) d[k] = z[k];
    for (int64_t c = c0; c < c1; ++c) part_rz[c] = chunk_dot(r, z, c);
    sync();
    double rz = total(part_rz);
    const double stop = stop_ratio * rz;
    // Every thread computes the same sums in the same order, so all leave the loop together.
    for (int it = 0; it < iterations && rz > stop && rz > 0; ++it) {
      multiply(d, q, r0, r1);
      for (int64_t c = c0; c < c1; ++c) part_dq[c] = chunk_dot(d, q, c);
      sync();
      const double dq = total(part_dq);
      if (!(dq > 0)) break;
      const double alpha = rz / dq;
      for (int64_t k = 3 * r0; k < 3 * r1; ++k) x[k] += alpha * d[k], r[k] -= alpha * q[k];
      precondition(r, z, r0, r1);
      for (int64_t c = c0; c < c1; ++c) part_rz[c] = chunk_dot(r, z, c);
      sync();
      const double rz_next = total(part_rz);
      const double beta = rz_next / rz;
      rz = rz_next;
      for (int64_t k = 3 * r0; k < 3 * r1; ++k) d[k] = z[k] + beta * d[k];
      sync();  // d complete before the next product reads other threads' rows
    }
  }
  return x;
}

}  // namespace layersnet::ad
