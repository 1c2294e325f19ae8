#pragma once
// A GSL random generator (gsl_rng_mt19937) owned RAII-style, whose whole state can be saved
// as bytes into a checkpoint and restored (gsl_rng_state / gsl_rng_size), so that a resumed
// run draws exactly the numbers an uninterrupted one would.
#include <gsl/gsl_rng.h>

#include <cstdint>
#include <string>
#include <vector>

namespace layersnet {

class GslRandom {
 public:
  explicit GslRandom(uint64_t seed);
  ~GslRandom();
  GslRandom(const GslRandom&) = delete;
  GslRandom& operator=(const GslRandom&) = delete;

  gsl_rng* get() const { return rng_; }
  // Uniform integer in [0, n] (inclusive).
  int uniform_int_inclusive(int n);
  // Fisher-Yates shuffle through gsl_ran_shuffle.
  template <class T>
  void shuffle(std::vector<T>& items);

  std::vector<uint8_t> state() const;
  // Restores bytes from state(); throws std::runtime_error naming `what` on a size mismatch.
  void set_state(const std::vector<uint8_t>& bytes, const std::string& what);

 private:
  void shuffle_bytes(void* base, std::size_t count, std::size_t size);
  gsl_rng* rng_ = nullptr;
};

template <class T>
void GslRandom::shuffle(std::vector<T>& items) {
  if (items.size() > 1) shuffle_bytes(items.data(), items.size(), sizeof(T));
}

}  // namespace layersnet
