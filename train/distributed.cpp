#include "train/distributed.h"

#include <algorithm>
#include <chrono>
#include <climits>
#include <cstdio>
#include <cstdlib>
#include <stdexcept>
#include <thread>

#ifdef LAYERSNET_HAVE_MPI
// The C API only: the deprecated C++ bindings would need libmpi_cxx.
#define OMPI_SKIP_MPICXX 1
#define MPICH_SKIP_MPICXX 1
#include <mpi.h>
#endif

namespace layersnet {

namespace {

#ifdef LAYERSNET_HAVE_MPI
// Started by mpirun (Open MPI, or a PMI/PMIx launcher): only then is MPI initialised, so a
// plain run never pays for it or depends on a launcher.
bool launched_by_mpirun() {
  for (const char* v : {"OMPI_COMM_WORLD_SIZE", "PMIX_RANK", "PMI_SIZE"})
    if (std::getenv(v)) return true;
  return false;
}

void finalize_at_exit() {
  int finalized = 0;
  MPI_Finalized(&finalized);
  if (!finalized) MPI_Finalize();
}

void check(int status, const char* what) {
  if (status != MPI_SUCCESS) throw std::runtime_error(std::string("MPI: ") + what + " failed");
}

int as_count(int64_t n) {
  if (n > INT_MAX) throw std::runtime_error("MPI: a message of " + std::to_string(n) + " elements exceeds MPI's int count");
  return static_cast<int>(n);
}

// Rank q sums the entries [slice_begin(P, q, R), slice_begin(P, q + 1, R)).
int64_t slice_begin(int64_t p, int q, int ranks) { return p * q / ranks; }
#endif

}  // namespace

Ranks::Ranks() {
#ifdef LAYERSNET_HAVE_MPI
  if (!launched_by_mpirun()) return;
  int provided = 0;
  check(MPI_Init_thread(nullptr, nullptr, MPI_THREAD_FUNNELED, &provided), "MPI_Init_thread");
  std::atexit(finalize_at_exit);
  // Errors come back as codes (turned into exceptions, then abort_job), not MPI's own abort.
  MPI_Comm_set_errhandler(MPI_COMM_WORLD, MPI_ERRORS_RETURN);
  MPI_Comm_rank(MPI_COMM_WORLD, &rank_);
  MPI_Comm_size(MPI_COMM_WORLD, &size_);
#endif
}

Ranks& Ranks::world() {
  static Ranks ranks;
  return ranks;
}

int64_t Ranks::mean_in_sample_order(std::span<float> out, const std::vector<std::span<const float>>& local, int n) const {
  const float inv = 1.0f / static_cast<float>(n);
  // Sums entries [b, e) of the n gradients, sample(i) giving g_i's entries from b on.
  auto sum_slice = [&](int64_t b, int64_t e, auto&& sample) {
    std::fill(out.begin() + b, out.begin() + e, 0.0f);
    for (int i = 0; i < n; ++i) {
      const float* src = sample(i);
      for (int64_t k = b; k < e; ++k) out[static_cast<std::size_t>(k)] += src[k - b] * inv;
    }
  };
  const auto p = static_cast<int64_t>(out.size());
  if (size_ == 1) {
    sum_slice(0, p, [&](int i) { return local[static_cast<std::size_t>(i)].data(); });
    return 0;
  }
#ifdef LAYERSNET_HAVE_MPI
  const int me = rank_;
  const int64_t mine = slice_begin(p, me + 1, size_) - slice_begin(p, me, size_);
  const int nl = local_count(n);
  // To rank q: slice q of each local gradient, in local order.
  std::vector<int> send_counts(static_cast<std::size_t>(size_)), send_displs(send_counts), recv_counts(send_counts),
      recv_displs(send_counts);
  std::vector<float> send(static_cast<std::size_t>(nl) * static_cast<std::size_t>(p));
  int64_t at = 0, sent_bytes = 0;
  for (int q = 0; q < size_; ++q) {
    const int64_t b = slice_begin(p, q, size_), e = slice_begin(p, q + 1, size_);
    send_displs[static_cast<std::size_t>(q)] = as_count(at);
    for (int j = 0; j < nl; ++j) {
      const auto& g = local[static_cast<std::size_t>(j)];
      std::copy(g.begin() + b, g.begin() + e, send.begin() + at);
      at += e - b;
    }
    send_counts[static_cast<std::size_t>(q)] = as_count(at - send_displs[static_cast<std::size_t>(q)]);
    if (q != me) sent_bytes += static_cast<int64_t>(send_counts[static_cast<std::size_t>(q)]) * 4;
  }
  int64_t rat = 0;
  for (int r = 0; r < size_; ++r) {
    recv_displs[static_cast<std::size_t>(r)] = as_count(rat);
    recv_counts[static_cast<std::size_t>(r)] = as_count(static_cast<int64_t>(r < n ? (n - r + size_ - 1) / size_ : 0) * mine);
    rat += recv_counts[static_cast<std::size_t>(r)];
  }
  std::vector<float> recv(static_cast<std::size_t>(rat));
  check(MPI_Alltoallv(send.data(), send_counts.data(), send_displs.data(), MPI_FLOAT, recv.data(), recv_counts.data(),
                      recv_displs.data(), MPI_FLOAT, MPI_COMM_WORLD),
        "MPI_Alltoallv (gradients)");
  const int64_t b = slice_begin(p, me, size_);
  sum_slice(b, b + mine, [&](int i) {
    return recv.data() + recv_displs[static_cast<std::size_t>(i % size_)] + static_cast<int64_t>(i / size_) * mine;
  });
  std::vector<int> counts(static_cast<std::size_t>(size_)), displs(counts);
  for (int q = 0; q < size_; ++q) {
    displs[static_cast<std::size_t>(q)] = as_count(slice_begin(p, q, size_));
    counts[static_cast<std::size_t>(q)] = as_count(slice_begin(p, q + 1, size_) - slice_begin(p, q, size_));
  }
  check(MPI_Allgatherv(MPI_IN_PLACE, 0, MPI_DATATYPE_NULL, out.data(), counts.data(), displs.data(), MPI_FLOAT,
                       MPI_COMM_WORLD),
        "MPI_Allgatherv (gradients)");
  return sent_bytes + mine * 4 * (size_ - 1);
#else
  throw std::logic_error("Ranks: more than one rank without MPI");
#endif
}

std::vector<double> Ranks::gather_items(const std::vector<double>& local, int n, int width) const {
  if (size_ == 1) return local;
#ifdef LAYERSNET_HAVE_MPI
  std::vector<int> counts(static_cast<std::size_t>(size_)), displs(counts);
  int at = 0;
  for (int r = 0; r < size_; ++r) {
    displs[static_cast<std::size_t>(r)] = at;
    counts[static_cast<std::size_t>(r)] = (r < n ? (n - r + size_ - 1) / size_ : 0) * width;
    at += counts[static_cast<std::size_t>(r)];
  }
  if (static_cast<int>(local.size()) != counts[static_cast<std::size_t>(rank_)])
    throw std::logic_error("Ranks::gather_items: wrong local size");
  std::vector<double> by_rank(static_cast<std::size_t>(at));
  check(MPI_Allgatherv(local.data(), counts[static_cast<std::size_t>(rank_)], MPI_DOUBLE, by_rank.data(), counts.data(),
                       displs.data(), MPI_DOUBLE, MPI_COMM_WORLD),
        "MPI_Allgatherv (items)");
  // Rank-major -> item order.
  std::vector<double> items(static_cast<std::size_t>(n) * static_cast<std::size_t>(width));
  for (int i = 0; i < n; ++i)
    std::copy_n(by_rank.begin() + displs[static_cast<std::size_t>(i % size_)] + (i / size_) * width, width,
                items.begin() + static_cast<int64_t>(i) * width);
  return items;
#else
  (void)n;
  (void)width;
  throw std::logic_error("Ranks: more than one rank without MPI");
#endif
}

std::string Ranks::broadcast(const std::string& text) const {
  if (size_ == 1) return text;
#ifdef LAYERSNET_HAVE_MPI
  int64_t length = rank_ == 0 ? static_cast<int64_t>(text.size()) : 0;
  check(MPI_Bcast(&length, 1, MPI_INT64_T, 0, MPI_COMM_WORLD), "MPI_Bcast");
  std::string out = rank_ == 0 ? text : std::string(static_cast<std::size_t>(length), '\0');
  check(MPI_Bcast(out.data(), as_count(length), MPI_CHAR, 0, MPI_COMM_WORLD), "MPI_Bcast");
  return out;
#else
  throw std::logic_error("Ranks: more than one rank without MPI");
#endif
}

void Ranks::abort_job(const std::string& message, int code) const {
  // A failure every rank meets (a missing file, say) is reported once: rank 0 ends the job
  // before the others speak.
  if (rank_ != 0) std::this_thread::sleep_for(std::chrono::seconds(2));
  std::fprintf(stderr, "error: %s\n", message.c_str());
  if (size_ > 1)
    std::fprintf(stderr, "(rank %d of %d; stopping all %d ranks)\n", rank_, size_, size_);
  std::fflush(stderr);
  std::fflush(stdout);
#ifdef LAYERSNET_HAVE_MPI
  if (size_ > 1) MPI_Abort(MPI_COMM_WORLD, code);
#endif
  std::exit(code);
}

}  // namespace layersnet
