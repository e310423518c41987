#pragma once
// Decoded bricks of a store (io/store_reader.h) shared by all threads under a byte budget.
//
// A hit copies the brick's pointer under one of 64 striped locks (no lock shared by all bricks, held
// for a pointer copy); a miss takes one of 64 other striped locks, so two threads wanting the same
// brick decode it once, then reads it with
// pread, decompresses it (and rebuilds band 0's records) and admits it. Eviction is CLOCK, a
// cheap LRU approximation: a hit sets the brick's reference bit, and the hand evicts bricks whose
// bit it finds clear until the decoded bytes are within the budget. A brick evicted while a
// reader still holds it lives on until that reader lets go (io/paged_volume.h keeps a few per
// thread), so the memory in use stays within the budget plus those few bricks per thread; and
// a miss on such a brick takes it back instead of decoding it again. A band-0 brick's values with
// their halo (get_halo_values: no records rebuilt) are an entry of their own, under the same
// budget and hand.
#include <atomic>
#include <cstdint>
#include <memory>
#include <mutex>
#include <vector>

#include "io/brick_pool.h"
#include "io/store_format.h"
#include "io/store_reader.h"

namespace isotope {

// A brick as the traversal reads it: values in Morton order, records by brick_record_index.
struct DecodedBrick {
  const float* values;
  const Record* records;
};

// Band 0's values of a brick with their halo, as stored (io/store_brick.h, halo_index): every
// node a block of finest cells inside the brick needs, without rebuilding the brick's records
// (most of a band-0 decode). What an eps-0 extraction reads (engine/finest_extract.h).
struct HaloValues {
  const float* values;
};

struct BrickCacheStats {
  int64_t bricks_read = 0;   // misses: bricks read, checked and decoded
  uint64_t bytes_read = 0;   // compressed bytes read for them
  int64_t hits = 0;          // lookups served from memory
  uint64_t peak_bytes = 0;   // most decoded bytes held at once
};

class BrickCache {
 public:
  // Below kMinBricks bricks a traversal's working set (its region's bricks in a few bands) does
  // not fit and every step decodes again (bolt, eps 0, 2 threads: 7.9 s with room for one brick,
  // 0.28 s with seven), so the budget is at least that many bricks (about 11 MB for 32^3 bricks: 1.33 MB each).
  static constexpr uint64_t kMinBricks = 8;
  BrickCache(const StoreReader& store, uint64_t budget_bytes);
  BrickCache(const BrickCache&) = delete;
  BrickCache& operator=(const BrickCache&) = delete;

  // Brick `index` of the store's directory, decoded. Thread-safe. Throws IoError naming the
  // brick when it cannot be read or is corrupt.
  std::shared_ptr<const DecodedBrick> get(int64_t index);
  // Band-0 brick `index`'s values with their halo. Thread-safe; throws as get(). Held apart from
  // get()'s bricks, under the same budget.
  std::shared_ptr<const HaloValues> get_halo_values(int64_t index);

  const StoreReader& store() const { return store_; }
  uint64_t budget_bytes() const { return budget_; }  // as given, raised to kMinBricks bricks
  uint64_t brick_bytes() const { return pool_->block_bytes(); }  // a brick decoded whole, the largest entry
  BrickCacheStats stats() const;

 private:
  // brick and evicted are guarded by slot_locks_[index % kStripes]: held for a pointer copy only.
  // (std::atomic<std::shared_ptr> would do without them, but GCC 12's is not race-free by the
  // memory model: its load releases its internal lock with a relaxed store; ThreadSanitizer
  // reports it, google/sanitizers#1558.)
  // Slot i < directory size holds brick i decoded whole (DecodedBrick), slot directory size + i
  // its halo values (HaloValues).
  struct Slot {
    std::shared_ptr<const void> brick;
    // After eviction: still alive while some reader holds it, and then taken back, not decoded
    // again (readers keep their recent bricks, so a small budget does not thrash on those).
    std::weak_ptr<const void> evicted;
    std::atomic<bool> referenced{false};
  };
  struct Resident {
    int64_t slot;
    uint64_t bytes;
  };
  template <class Decode>
  std::shared_ptr<const void> get_slot(int64_t slot, int64_t index, BrickPool& pool, const Decode& decode);
  void admit(int64_t slot, uint64_t bytes);
  std::shared_ptr<const DecodedBrick> decode(int64_t index);
  std::shared_ptr<const HaloValues> decode_halo(int64_t index);
  std::shared_ptr<const void> resident(int64_t slot);
  void publish(int64_t slot, const std::shared_ptr<const void>& brick, uint64_t bytes);

  const StoreReader& store_;
  const uint64_t budget_;
  std::shared_ptr<BrickPool> pool_;       // shared with the bricks' deleters
  std::shared_ptr<BrickPool> halo_pool_;  // for the HaloValues
  std::unique_ptr<Slot[]> slots_;
  static constexpr size_t kStripes = 64;
  std::mutex slot_locks_[kStripes];  // short: a pointer copy
  std::mutex load_locks_[kStripes];  // long: one brick's read and decode, so it is done once
  mutable std::mutex clock_mutex_;  // the resident list and the hand; taken on misses only
  std::vector<Resident> resident_;
  size_t hand_ = 0;
  uint64_t resident_bytes_ = 0, peak_bytes_ = 0;
  std::atomic<int64_t> hits_{0}, bricks_read_{0};
  std::atomic<uint64_t> bytes_read_{0};
};

}  // namespace isotope
