#pragma once
// Memory for decoded bricks (BrickCache): blocks of one fixed size carved from 16 MB chunks
// and recycled through a free list, so that a brick evicted leaves its memory, already faulted in,
// to the next one decoded. Chunks are kept until the pool goes; untouched parts of a chunk cost no
// memory.
#include <cstddef>
#include <mutex>
#include <vector>

namespace isotope {

class BrickPool {
 public:
  explicit BrickPool(size_t block_bytes);
  ~BrickPool();
  BrickPool(const BrickPool&) = delete;
  BrickPool& operator=(const BrickPool&) = delete;

  size_t block_bytes() const { return block_; }
  void* allocate();           // thread-safe; throws std::bad_alloc
  void release(void* block);  // thread-safe

 private:
  size_t block_;
  // A new block past the pages faulted in faults in this much more at once (detail::prefault).
  static constexpr size_t kPopulateAhead = size_t{256} << 10;

  std::mutex mutex_;
  std::vector<void*> free_;
  std::vector<void*> chunks_;
  char* next_ = nullptr;  // unused tail of the newest chunk
  char* end_ = nullptr;
  char* populated_ = nullptr;  // the newest chunk's pages up to here are faulted in, or being so
};

}  // namespace isotope
