#include "io/brick_cache.h"

#include <algorithm>

#include "io/store_brick.h"

namespace isotope {
namespace {

// Bricks worth of file read ahead of each miss (io/store_reader.h, prefetch_after).
constexpr int kPrefetchBricks = 4;

size_t block_bytes(const StoreLayout& layout) {
  return static_cast<size_t>(layout.brick_nodes()) * sizeof(float) + static_cast<size_t>(layout.brick_records()) * sizeof(Record);
}

size_t halo_bytes(const StoreLayout& layout) {
  const auto w = static_cast<size_t>(halo_width(layout));
  return w * w * w * sizeof(float);
}

}  // namespace

BrickCache::BrickCache(const StoreReader& store, uint64_t budget_bytes)
    : store_(store), budget_(std::max<uint64_t>(budget_bytes, kMinBricks * block_bytes(store.layout()))),
      pool_(std::make_shared<BrickPool>(block_bytes(store.layout()))),
      halo_pool_(std::make_shared<BrickPool>(halo_bytes(store.layout()))),
      slots_(new Slot[2 * store.directory().size()]) {}

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

std::shared_ptr<const HaloValues> BrickCache::decode_halo(int64_t index) {
  const std::vector<float> halo = store_.read_stored_values(index);
  auto* values = static_cast<float*>(halo_pool_->allocate());
  std::copy(halo.begin(), halo.end(), values);
  std::shared_ptr<BrickPool> pool = halo_pool_;
  return std::shared_ptr<const HaloValues>(new HaloValues{values}, [pool](const HaloValues* b) {
    pool->release(const_cast<float*>(b->values));
    delete b;
  });
}

std::shared_ptr<const void> BrickCache::resident(int64_t slot) {
  const std::lock_guard<std::mutex> lock(slot_locks_[static_cast<size_t>(slot) % kStripes]);
  return slots_[static_cast<size_t>(slot)].brick;
}

void BrickCache::publish(int64_t slot, const std::shared_ptr<const void>& brick, uint64_t bytes) {
  {
    const std::lock_guard<std::mutex> lock(slot_locks_[static_cast<size_t>(slot) % kStripes]);
    slots_[static_cast<size_t>(slot)].brick = brick;
  }
  slots_[static_cast<size_t>(slot)].referenced.store(true, std::memory_order_relaxed);
  admit(slot, bytes);
}

template <class Decode>
std::shared_ptr<const void> BrickCache::get_slot(int64_t slot_index, int64_t index, BrickPool& pool,
                                                 const Decode& decode) {
  Slot& slot = slots_[static_cast<size_t>(slot_index)];
  auto found = resident(slot_index);
  if (!found) {
    const std::lock_guard<std::mutex> lock(load_locks_[static_cast<size_t>(slot_index) % kStripes]);
    found = resident(slot_index);  // another thread may have loaded it meanwhile
    if (!found) {
      {  // evicted, but still held by a reader?
        const std::lock_guard<std::mutex> slot_lock(slot_locks_[static_cast<size_t>(slot_index) % kStripes]);
        found = slot.evicted.lock();
      }
      if (found) {
        publish(slot_index, found, pool.block_bytes());
      } else {
        store_.prefetch_after(index, kPrefetchBricks);
        found = decode(index);
        bricks_read_.fetch_add(1, std::memory_order_relaxed);
        bytes_read_.fetch_add(store_.directory()[static_cast<size_t>(index)].compressed_bytes, std::memory_order_relaxed);
        publish(slot_index, found, pool.block_bytes());
        return found;
      }
    }
  }
  hits_.fetch_add(1, std::memory_order_relaxed);
  if (!slot.referenced.load(std::memory_order_relaxed)) slot.referenced.store(true, std::memory_order_relaxed);
  return found;
}

std::shared_ptr<const DecodedBrick> BrickCache::get(int64_t index) {
  return std::static_pointer_cast<const DecodedBrick>(
      get_slot(index, index, *pool_, [this](int64_t i) { return decode(i); }));
}

std::shared_ptr<const HaloValues> BrickCache::get_halo_values(int64_t index) {
  const auto slot = static_cast<int64_t>(store_.directory().size()) + index;
  return std::static_pointer_cast<const HaloValues>(
      get_slot(slot, index, *halo_pool_, [this](int64_t i) { return decode_halo(i); }));
}

void BrickCache::admit(int64_t slot_index, uint64_t bytes) {
  const std::lock_guard<std::mutex> lock(clock_mutex_);
  resident_.push_back({slot_index, bytes});
  resident_bytes_ += bytes;
  peak_bytes_ = std::max(peak_bytes_, resident_bytes_);
  while (resident_bytes_ > budget_ && resident_.size() > 1) {
    if (hand_ >= resident_.size()) hand_ = 0;
    const Resident victim = resident_[hand_];
    Slot& slot = slots_[static_cast<size_t>(victim.slot)];
    if (victim.slot == slot_index || slot.referenced.exchange(false, std::memory_order_relaxed)) {
      ++hand_;  // a second chance
      continue;
    }
    {
      const std::lock_guard<std::mutex> slot_lock(slot_locks_[static_cast<size_t>(victim.slot) % kStripes]);
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
