#pragma once
// The processes of one training job. `mpirun -np R layersnet train ...` runs R ranks of data
// parallelism (MPI, when the build found it); a plain `layersnet train`, or a build without
// MPI, is one rank and never touches MPI.
//
// Every rank holds the whole model. Sample i of a global batch of n lives on rank i mod R (its
// local index i / R). The collectives below are called by all ranks in the same order, from the
// thread that called Ranks::world() first (MPI_THREAD_FUNNELED).
#include <cstdint>
#include <span>
#include <string>
#include <vector>

namespace layersnet {

class Ranks {
 public:
  // The job's ranks; the first call initialises MPI when launched by mpirun (MPI is finalised
  // at exit).
  static Ranks& world();

  int rank() const { return rank_; }
  int size() const { return size_; }
  bool distributed() const { return size_ > 1; }
  // Samples of a batch of n on this rank (indices rank, rank + R, ...).
  int local_count(int n) const { return rank_ < n ? (n - rank_ + size_ - 1) / size_ : 0; }
  bool owns(int64_t i) const { return i % size_ == rank_; }

  // out (P,) = (1/n) Σ_{i=0..n-1} g_i, added in sample order i = 0, 1, ... from 0.0f on every
  // rank, where local[j] (P,) is g_{rank + j·R}: bit-identical to one process summing the same
  // n gradients. Each rank sums a slice of the P entries over all n samples (all-to-all), then
  // the slices are all-gathered. Returns the bytes this rank sent to other ranks.
  int64_t mean_in_sample_order(std::span<float> out, const std::vector<std::span<const float>>& local, int n) const;

  // values of all n items (width doubles each) in item order, item i from rank i mod R, whose
  // local (local_count(n) · width,) holds its items in local order.
  std::vector<double> gather_items(const std::vector<double>& local, int n, int width) const;

  // Rank 0's text on every rank.
  std::string broadcast(const std::string& text) const;

  // Prints "error: <message>" (naming the rank when distributed) and ends the whole job with
  // `code`: MPI_Abort stops every rank, so no rank is left waiting in a collective.
  [[noreturn]] void abort_job(const std::string& message, int code) const;

 private:
  Ranks();
  int rank_ = 0, size_ = 1;
};

}  // namespace layersnet
