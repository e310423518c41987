#include "io/store/brick_pool.h"

#include <algorithm>

#include "engine/core/huge_blocks.h"

namespace isotope {

BrickPool::BrickPool(size_t block_bytes) : block_((block_bytes + 63) / 64 * 64) {}

BrickPool::~BrickPool() {
  for (void* c : chunks_) detail::free_huge(c);
}

void* BrickPool::allocate() {
  std::unique_lock<std::mutex> lock(mutex_);
  if (!free_.empty()) {
    void* p = free_.back();
    free_.pop_back();
    return p;
  }
  if (next_ == nullptr || static_cast<size_t>(end_ - next_) < block_) {
    constexpr size_t kHuge = detail::kHugePage;
    const size_t chunk = std::max<size_t>(8 * kHuge, (block_ + kHuge - 1) / kHuge * kHuge);
    void* c = detail::allocate_huge(chunk);
    try {
      chunks_.push_back(c);
    } catch (...) {
      detail::free_huge(c);
      throw;
    }
    next_ = static_cast<char*>(c);
    end_ = next_ + chunk;
    populated_ = next_;
  }
  void* p = next_;
  next_ += block_;
  if (next_ <= populated_) return p;
  char* from = populated_;
  populated_ = std::min(end_, std::max(next_, populated_ + kPopulateAhead));
  const size_t bytes = static_cast<size_t>(populated_ - from);
  lock.unlock();  // another thread may take a block of these pages meanwhile: it faults them in itself
  detail::prefault(from, bytes);
  return p;
}

void BrickPool::release(void* block) {
  const std::lock_guard<std::mutex> lock(mutex_);
  free_.push_back(block);
}

}  // namespace isotope
