#include "autodiff/arena.h"

#include <sys/mman.h>

#if defined(__GLIBC__)
#include <malloc.h>
#endif

#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <new>
#include <stdexcept>
#include <string>

namespace layersnet {
extern int aligned_new_anchor;  // autodiff/aligned_new.cpp: 64-byte aligned heap, the same bits every run
}  // namespace layersnet

namespace layersnet::ad {

namespace {
// Refers to the anchor, so every program with a tape links the aligned operator new.
[[maybe_unused]] const int* const kAlignedNew = &aligned_new_anchor;
std::size_t round_up(std::size_t n, std::size_t a) { return (n + a - 1) / a * a; }
}  // namespace

void keep_freed_memory_in_process() {
#if defined(__GLIBC__)
  mallopt(M_MMAP_MAX, 0);
  mallopt(M_TRIM_THRESHOLD, -1);
  mallopt(M_ARENA_MAX, 1);
#endif
}

Arena::Arena(std::size_t first_block_bytes) {
  blocks_.reserve(64);  // the block list itself must not reallocate in steady state
  add_block(first_block_bytes);
}

Arena::~Arena() {
  for (auto& b : blocks_) munmap(b.data, b.size);
}

// Blocks come straight from the kernel (mmap, page-aligned, so 64-byte aligned too), not from
// malloc: when rewind() merges the blocks, the old ones go back to the system at once. From
// malloc's heap (kept resident by a program that tunes malloc not to trim, as the benchmarks
// do) the merged block came on top of them, and the step's peak counted the arena twice.
void Arena::add_block(std::size_t min_bytes) {
  std::size_t size = blocks_.empty() ? min_bytes : blocks_.back().size * 2;
  if (size < min_bytes) size = min_bytes;
  size = round_up(size < kAlignment ? kAlignment : size, kAlignment);
  void* p = mmap(nullptr, size, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
  if (p == MAP_FAILED) throw std::bad_alloc();
  // A hint, as for the gradient region: a merged block is faulted in afresh, one fault per
  // 2 MiB instead of 512.
  madvise(p, size, MADV_HUGEPAGE);
  ++heap_allocations_;
  blocks_.push_back({static_cast<std::byte*>(p), size});
}

void* Arena::allocate(std::size_t bytes) {
  const std::size_t need = round_up(bytes == 0 ? 1 : bytes, kAlignment);
  while (offset_ + need > blocks_[current_].size) {
    used_in_previous_blocks_ += offset_;
    offset_ = 0;
    if (current_ + 1 == blocks_.size()) add_block(need);
    ++current_;
  }
  void* p = blocks_[current_].data + offset_;
  offset_ += need;
  return p;
}

void Arena::rewind() {
  if (blocks_.size() > 1) {
    // Merge: next step of the same shape then fits in one block, with no heap traffic.
    const std::size_t total = capacity();
    for (auto& b : blocks_) munmap(b.data, b.size);
    blocks_.clear();
    add_block(total);
  }
  current_ = 0;
  offset_ = 0;
  used_in_previous_blocks_ = 0;
}

std::size_t Arena::bytes_in_use() const { return used_in_previous_blocks_ + offset_; }

std::size_t Arena::capacity() const {
  std::size_t total = 0;
  for (const auto& b : blocks_) total += b.size;
  return total;
}

GradRegion::~GradRegion() {
  if (base_) munmap(base_, reserved_);
}

void* GradRegion::allocate(std::size_t bytes) {
  if (!base_) {
    // Address space only (MAP_NORESERVE): nothing is committed until written. 256 GiB first
    // (a D-LAYERS-size training step reserves under 1 GiB; the 128 TiB address space holds
    // hundreds of tapes), smaller if the kernel refuses (e.g. a limited address space).
    for (std::size_t size = std::size_t{1} << 38; size >= (std::size_t{1} << 30); size >>= 2) {
      void* p = mmap(nullptr, size + kPage, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS | MAP_NORESERVE, -1, 0);
      if (p == MAP_FAILED) continue;
      // Align the start to a huge page, so that whole 2 MiB pages can be released.
      auto* raw = static_cast<std::byte*>(p);
      const auto mis = reinterpret_cast<std::uintptr_t>(raw) % kPage;
      const std::size_t head = mis ? kPage - mis : 0;
      if (head) munmap(raw, head);
      if (kPage - head) munmap(raw + head + size, kPage - head);
      base_ = raw + head;
      reserved_ = size;
      madvise(base_, reserved_, MADV_HUGEPAGE);  // a hint; without THP the region works with 4 KiB pages
      break;
    }
    if (!base_)
      throw std::runtime_error(std::string("tape: cannot reserve address space for gradients (mmap: ") +
                               std::strerror(errno) + "); raise the process's address-space limit (ulimit -v)");
  }
  const std::size_t need = round_up(bytes == 0 ? 1 : bytes, kAlignment);
  if (top_ + need > reserved_)
    throw std::runtime_error("tape: gradients of one step exceed the " + std::to_string(reserved_ >> 30) +
                             " GiB of reserved address space; raise the address-space limit (ulimit -v)");
  void* p = base_ + top_;
  top_ += need;
  if (top_ > dirty_end_) dirty_end_ = top_;
  if (top_ > peak_top_) peak_top_ = top_;
  return p;
}

void GradRegion::release_from(std::size_t offset) {
  const std::size_t from = round_up(offset, kPage);
  const std::size_t to = round_up(dirty_end_, kPage);
  if (from >= to) return;
  madvise(base_ + from, to - from, MADV_DONTNEED);  // private anonymous memory: reads as zero afterwards
  dirty_end_ = from;
}

void GradRegion::rewind() {
  if (base_ && dirty_end_ > 0) {
    madvise(base_, round_up(dirty_end_, kPage), MADV_DONTNEED);
    dirty_end_ = 0;
  }
  top_ = 0;
}

}  // namespace layersnet::ad
