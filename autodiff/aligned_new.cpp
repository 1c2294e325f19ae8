// Every C++ heap allocation of the program 64-byte aligned.
//
// Why: Eigen's vectorised reductions and matrix-vector kernels peel a data-dependent number
// of leading elements to reach an aligned address, so the summation order — and the last
// bits of a float result — depend on where the heap put a buffer (std::vector<float> from
// malloc is only 16-byte aligned). A resumed process has another heap history than the
// uninterrupted run, and its parameters drifted apart by rounding within a few updates.
// With every operator-new buffer on a 64-byte boundary (one cache line, one AVX-512
// register) the address modulo the vector width is always 0 and the arithmetic identical:
// same seed + threads give the same bits, and --resume continues bit-exactly.
//
// Replacing the global allocation functions is standard C++ ([replacement.functions]); this
// object file is linked into any program that builds a tape (autodiff/arena.cpp refers to it),
// so training, evaluation, the tests and a library user's program all get the same bits.
#include <cstdlib>
#include <new>

namespace {

void* aligned_or_null(std::size_t n) noexcept {
  const std::size_t bytes = (n == 0 ? 64 : (n + 63) / 64 * 64);  // aligned_alloc wants a multiple
  return std::aligned_alloc(64, bytes);
}

void* aligned_or_throw(std::size_t n) {
  void* p = aligned_or_null(n);
  if (!p) throw std::bad_alloc();
  return p;
}

}  // namespace

namespace layersnet {
// Referenced from arena.cpp so that the linker keeps this object file.
int aligned_new_anchor = 0;
}  // namespace layersnet

void* operator new(std::size_t n) { return aligned_or_throw(n); }
void* operator new[](std::size_t n) { return aligned_or_throw(n); }
void* operator new(std::size_t n, const std::nothrow_t&) noexcept { return aligned_or_null(n); }
void* operator new[](std::size_t n, const std::nothrow_t&) noexcept { return aligned_or_null(n); }
void operator delete(void* p) noexcept { std::free(p); }
void operator delete[](void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }
void operator delete[](void* p, std::size_t) noexcept { std::free(p); }
void operator delete(void* p, const std::nothrow_t&) noexcept { std::free(p); }
void operator delete[](void* p, const std::nothrow_t&) noexcept { std::free(p); }
