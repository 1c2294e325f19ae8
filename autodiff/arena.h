#pragma once
// Bump allocator for the memory of one training or rollout step (Stan's stack allocator).
//
// Every tensor the tape creates lives here; `rewind()` after the step frees it all at once.
// Blocks double in size; on rewind, several blocks are merged into one of their total size,
// so from the second step on a step of the same shape makes no heap allocation at all.
// All allocations are 64-byte aligned (one cache line, one AVX-512 register).
#include <cstddef>
#include <cstdint>
#include <vector>

namespace layersnet::ad {

// Freed heap memory stays with the process: no allocation gets its own mmap, the heap is never
// trimmed, all threads share one malloc arena. A model step frees and allocates the same sizes
// every time (sample building, GEMM packing, the losses' index lists); without this glibc hands
// them back and the next step page-faults them in again. Call once, before the first step;
// does nothing outside glibc.
void keep_freed_memory_in_process();

class Arena {
 public:
  static constexpr std::size_t kAlignment = 64;

  explicit Arena(std::size_t first_block_bytes = std::size_t{1} << 20);
  ~Arena();
  Arena(const Arena&) = delete;
  Arena& operator=(const Arena&) = delete;

  // Uninitialised, 64-byte aligned; `bytes` may be 0 (returns a valid, unique-enough pointer).
  void* allocate(std::size_t bytes);

  template <class U>
  U* allocate_array(std::size_t count) {
    return static_cast<U*>(allocate(count * sizeof(U)));
  }

  // Frees every allocation; keeps (and consolidates) the memory for the next step.
  void rewind();

  std::size_t bytes_in_use() const;     // since the last rewind, including alignment padding
  std::size_t capacity() const;         // bytes held from the heap
  std::size_t heap_allocations() const { return heap_allocations_; }  // blocks ever allocated

 private:
  struct Block {
    std::byte* data;
    std::size_t size;
  };
  void add_block(std::size_t min_bytes);

  std::vector<Block> blocks_;
  std::size_t current_ = 0;  // index of the block being filled
  std::size_t offset_ = 0;   // bytes used in blocks_[current_]
  std::size_t used_in_previous_blocks_ = 0;
  std::size_t heap_allocations_ = 0;
};

// Address space for the gradients of op outputs, committed by the OS only where backward
// writes and handed back as soon as backward no longer needs it.
//
// Why not the arena: gradients are written in backward only, and the gradient of an op's
// output is dead once that op's backward has run. Reserved (not committed) at forward time,
// they cost no memory until backward touches them; released behind the backward walk
// (madvise DONTNEED), the step's peak is the forward's values plus the gradients live at
// one point of the walk, not values plus every gradient. Fresh and released pages read as
// zero, so the forward no longer zeroes gradients. Transparent huge pages are requested:
// one fault and one kernel page clear per 2 MiB instead of 512.
//
// Allocation is a bump pointer (64-byte aligned, like the arena); `release_from(offset)`
// gives back every whole 2 MiB page at or above `offset` that may hold data.
class GradRegion {
 public:
  static constexpr std::size_t kAlignment = 64;
  static constexpr std::size_t kPage = std::size_t{2} << 20;

  GradRegion() = default;
  ~GradRegion();
  GradRegion(const GradRegion&) = delete;
  GradRegion& operator=(const GradRegion&) = delete;

  // Zero-filled, 64-byte aligned. Reserves the address space on first use.
  void* allocate(std::size_t bytes);
  std::size_t top() const { return top_; }  // bytes handed out since the last rewind
  // Gives back the pages above `offset` (rounded up to a page); their bytes read as zero again.
  void release_from(std::size_t offset);
  // Releases everything and starts again at offset 0.
  void rewind();
  std::size_t peak_top() const { return peak_top_; }  // largest top() ever (address space, not memory)

 private:
  std::byte* base_ = nullptr;
  std::size_t reserved_ = 0;
  std::size_t top_ = 0;
  std::size_t dirty_end_ = 0;  // pages at or above this offset are known to read as zero
  std::size_t peak_top_ = 0;
};

}  // namespace layersnet::ad
