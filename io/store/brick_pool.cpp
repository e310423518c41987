#include "io/store/brick_pool.h"

#include <algorithm>

#include "isotope/detail/huge_page_allocator.h"

namespace isotope {

BrickPool::BrickPool(size_t block_bytes) : block_((block_bytes + 63) / 64 * 64) {}

BrickPool::~BrickPool() {
  for (void* c : chunks_) detail::free_huge(c);
}

void* BrickPool::allocate() {
  const std::lock_guard<std::mutex> lock(mutex_);
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
  }
  void* p = next_;
  next_ += block_;
  return p;
}

void BrickPool::release(void* block) {
  const std::lock_guard<std::mutex> lock(mutex_);
  free_.push_back(block);
}

}  // namespace isotope
