#include "io/brick_cache.h"

#include <algorithm>

namespace isotope {
namespace {

// Bricks worth of file read ahead of each miss (io/store_reader.h, prefetch_after).
constexpr int kPrefetchBricks = 4;

size_t block_bytes(const StoreLayout& layout) {
  return static_cast<size_t>(layout.brick_nodes()) * sizeof(float) + static_cast<size_t>(layout.brick_records()) * sizeof(Record);
}

}  // namespace

BrickCache::BrickCache(const StoreReader& store, uint64_t budget_bytes)
    : store_(store), budget_(std::max<uint64_t>(budget_bytes, kMinBricks * block_bytes(store.layout()))),
      pool_(std::make_shared<BrickPool>(block_bytes(store.layout()))),
      slots_(new Slot[store.directory().size()]) {}

std::shared_ptr<const DecodedBrick> BrickCache::decode(int64_t index) {
  const BrickContents c = store_.read_brick(index);
  void* block = pool_->allocate();
  auto* values = static_cast<float*>(block);
  auto* records = reinterpret_cast<Record*>(values + c.values.size());
  std::copy(c.values.begin(), c.values.end(), values);
  std::copy(c.records.begin(), c.records.end(), records);
  std::shared_ptr<BrickPool> pool = pool_;
  return std::shared_ptr<const DecodedBrick>(new DecodedBrick{values, records}, [pool](const DecodedBrick* b) {
    pool->release(const_cast<float*>(b->values));
    delete b;
  });
}

std::shared_ptr<const DecodedBrick> BrickCache::resident(int64_t index) {
  const std::lock_guard<std::mutex> lock(slot_locks_[static_cast<size_t>(index) % kStripes]);
  return slots_[static_cast<size_t>(index)].brick;
}

void BrickCache::publish(int64_t index, const std::shared_ptr<const DecodedBrick>& brick) {
  {
    const std::lock_guard<std::mutex> lock(slot_locks_[static_cast<size_t>(index) % kStripes]);
    slots_[static_cast<size_t>(index)].brick = brick;
  }
  slots_[static_cast<size_t>(index)].referenced.store(true, std::memory_order_relaxed);
  admit(index, pool_->block_bytes());
}

std::shared_ptr<const DecodedBrick> BrickCache::get(int64_t index) {
  Slot& slot = slots_[static_cast<size_t>(index)];
  auto found = resident(index);
  if (!found) {
    const std::lock_guard<std::mutex> lock(load_locks_[static_cast<size_t>(index) % kStripes]);
    found = resident(index);  // another thread may have loaded it meanwhile
    if (!found) {
      {  // evicted, but still held by a reader?
        const std::lock_guard<std::mutex> slot_lock(slot_locks_[static_cast<size_t>(index) % kStripes]);
        found = slot.evicted.lock();
      }
      if (found) {
        publish(index, found);
      } else {
        store_.prefetch_after(index, kPrefetchBricks);
        found = decode(index);
        bricks_read_.fetch_add(1, std::memory_order_relaxed);
        bytes_read_.fetch_add(store_.directory()[static_cast<size_t>(index)].compressed_bytes, std::memory_order_relaxed);
        publish(index, found);
        return found;
      }
    }
  }
  hits_.fetch_add(1, std::memory_order_relaxed);
  if (!slot.referenced.load(std::memory_order_relaxed)) slot.referenced.store(true, std::memory_order_relaxed);
  return found;
}

void BrickCache::admit(int64_t index, uint64_t bytes) {
  const std::lock_guard<std::mutex> lock(clock_mutex_);
  resident_.push_back({index, bytes});
  resident_bytes_ += bytes;
  peak_bytes_ = std::max(peak_bytes_, resident_bytes_);
  while (resident_bytes_ > budget_ && resident_.size() > 1) {
    if (hand_ >= resident_.size()) hand_ = 0;
    const Resident victim = resident_[hand_];
    Slot& slot = slots_[static_cast<size_t>(victim.index)];
    if (victim.index == index || slot.referenced.exchange(false, std::memory_order_relaxed)) {
      ++hand_;  // a second chance
      continue;
    }
    {
      const std::lock_guard<std::mutex> slot_lock(slot_locks_[static_cast<size_t>(victim.index) % kStripes]);
      slot.evicted = slot.brick;
      slot.brick.reset();
    }
    resident_bytes_ -= victim.bytes;
    resident_[hand_] = resident_.back();
    resident_.pop_back();
  }
}

BrickCacheStats BrickCache::stats() const {
  BrickCacheStats s;
  s.bricks_read = bricks_read_.load();
  s.bytes_read = bytes_read_.load();
  s.hits = hits_.load();
  const std::lock_guard<std::mutex> lock(clock_mutex_);
  s.peak_bytes = peak_bytes_;
  return s;
}

}  // namespace isotope
