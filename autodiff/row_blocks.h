#pragma once
// Row-block parallelism for kernels over (N, C) row-major tensors.
//
// Rows are cut into fixed blocks whose size depends only on C, and OpenMP spreads the
// blocks over threads. Reductions over rows write one partial per block and then add the
// partials in block order, so every result is bit-identical for any thread count.
// Small tensors (and calls from inside a parallel region) run serially.
#include <omp.h>

#include <algorithm>
#include <cstdint>
#include <vector>

namespace layersnet::ad {

// About 32k entries (128 KiB of floats) per block: big enough to amortise the call,
// small enough to stay in L2 and to balance two threads.
inline int64_t block_rows(int64_t cols) { return std::max<int64_t>(1, (int64_t{1} << 15) / std::max<int64_t>(cols, 1)); }

// Below this many entries the OpenMP fork costs more than it saves.
constexpr int64_t kParallelMinEntries = int64_t{1} << 16;

inline bool run_parallel(int64_t rows, int64_t cols) {
  return rows * cols >= kParallelMinEntries && !omp_in_parallel() && omp_get_max_threads() > 1;
}

// Calls f(r0, n) for the row blocks [r0, r0 + n) of an (rows, cols) tensor.
template <class F>
void for_row_blocks(int64_t rows, int64_t cols, F&& f) {
  const int64_t br = block_rows(cols);
  const int64_t n_blocks = (rows + br - 1) / br;
#pragma omp parallel for schedule(static) if (run_parallel(rows, cols))
  for (int64_t k = 0; k < n_blocks; ++k) {
    const int64_t r0 = k * br;
    f(r0, std::min(br, rows - r0));
  }
}

// Sum over rows of per-block results of width `width`: f(r0, n, partial) ADDS the
// contribution of rows [r0, r0 + n) into partial (width, zeroed). Returns the total
// (width values) in a per-thread buffer valid until the next call on this thread.
template <class T, class F>
const T* reduce_row_blocks(int64_t rows, int64_t cols, int64_t width, F&& f) {
  static thread_local std::vector<T> buffer;  // grows once, then reused: no steady-state allocation
  const int64_t br = block_rows(cols);
  const int64_t n_blocks = (rows + br - 1) / br;
  buffer.assign(static_cast<std::size_t>((n_blocks + 1) * width), T(0));
  T* base = buffer.data();
#pragma omp parallel for schedule(static) if (run_parallel(rows, cols))
  for (int64_t k = 0; k < n_blocks; ++k) {
    const int64_t r0 = k * br;
    f(r0, std::min(br, rows - r0), base + (k + 1) * width);
  }
  for (int64_t k = 1; k <= n_blocks; ++k) {
    const T* p = base + k * width;
    for (int64_t j = 0; j < width; ++j) base[j] += p[j];
  }
  return base;
}

// Scratch for one op kind's backward on this thread: grows to the largest request, then is
// reused by every later call, so what only backward needs is not held on the tape from the
// forward on (a forward's buffers that die with the call use it too). Contents are unspecified;
// valid until the next call with the same Slot.
template <class T, int Slot>
T* backward_scratch(std::size_t count) {
  static thread_local std::vector<T> buffer;
  if (buffer.size() < count) {
    buffer.clear();
    buffer.resize(count);
  }
  return buffer.data();
}

// Slots of backward_scratch (one per buffer an op needs at the same time).
enum ScratchSlot : int {
  kScratchLinearRelu,
  kScratchRiaWeights,
  kScratchRiaSenders,
  kScratchRotMapU,
  kScratchRotMapT,
  kScratchMlpGradA,
  kScratchMlpGradB,
  kScratchLayerNorm
};

}  // namespace layersnet::ad
