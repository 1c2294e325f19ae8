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

}  // namespace layersnet::ad
