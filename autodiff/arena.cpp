#include "autodiff/arena.h"

#include <cstdlib>
#include <new>

namespace layersnet {
extern int aligned_new_anchor;  // autodiff/aligned_new.cpp: 64-byte aligned heap, the same bits every run
}  // namespace layersnet

namespace layersnet::ad {

namespace {
// Refers to the anchor, so every program with a tape links the aligned operator new.
[[maybe_unused]] const int* const kAlignedNew = &aligned_new_anchor;
std::size_t round_up(std::size_t n, std::size_t a) { return (n + a - 1) / a * a; }
}  // namespace

Arena::Arena(std::size_t first_block_bytes) {
  blocks_.reserve(64);  // the block list itself must not reallocate in steady state
  add_block(first_block_bytes);
}

Arena::~Arena() {
  for (auto& b : blocks_) std::free(b.data);
}

void Arena::add_block(std::size_t min_bytes) {
  std::size_t size = blocks_.empty() ? min_bytes : blocks_.back().size * 2;
  if (size < min_bytes) size = min_bytes;
  size = round_up(size < kAlignment ? kAlignment : size, kAlignment);
  void* p = std::aligned_alloc(kAlignment, size);
  if (!p) throw std::bad_alloc();
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
    for (auto& b : blocks_) std::free(b.data);
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

}  // namespace layersnet::ad
