#include "train/gsl_random.h"

#include <gsl/gsl_randist.h>

#include <cstring>
#include <stdexcept>

namespace layersnet {

GslRandom::GslRandom(uint64_t seed) : rng_(gsl_rng_alloc(gsl_rng_mt19937)) {
  if (!rng_) throw std::runtime_error("gsl_rng_alloc(gsl_rng_mt19937) failed (out of memory?)");
  // mt19937 takes an unsigned long seed; GSL maps seed 0 to its default 4357, so 0 and
  // 4357 give the same stream — harmless, and documented by GSL.
  gsl_rng_set(rng_, static_cast<unsigned long>(seed));
}

GslRandom::~GslRandom() { gsl_rng_free(rng_); }

int GslRandom::uniform_int_inclusive(int n) {
  if (n <= 0) return 0;
  return static_cast<int>(gsl_rng_uniform_int(rng_, static_cast<unsigned long>(n) + 1));
}

void GslRandom::shuffle_bytes(void* base, std::size_t count, std::size_t size) {
  gsl_ran_shuffle(rng_, base, count, size);
}

std::vector<uint8_t> GslRandom::state() const {
  const auto* p = static_cast<const uint8_t*>(gsl_rng_state(rng_));
  return std::vector<uint8_t>(p, p + gsl_rng_size(rng_));
}

void GslRandom::set_state(const std::vector<uint8_t>& bytes, const std::string& what) {
  if (bytes.size() != gsl_rng_size(rng_))
    throw std::runtime_error(what + ": random generator state has " + std::to_string(bytes.size()) +
                             " bytes, gsl_rng_mt19937 needs " + std::to_string(gsl_rng_size(rng_)) +
                             " (checkpoint from another program version?)");
  std::memcpy(gsl_rng_state(rng_), bytes.data(), bytes.size());
}

}  // namespace layersnet
