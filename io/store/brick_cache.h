#pragma once
// Decoded bricks of a store (StoreReader) shared by all threads under a byte budget.
//
// A brick enters with its core section decoded (values; the range and bound of its records), and
// gains its other fields the first time an extraction reads them (require): a `none` extraction
// never decodes a critical interval. Band 0 stores no records: its bricks enter with their record
// arrays marked unset, and PagedVolume fills each record from the values the first time it is
// read. So the cost of a brick follows what the traversal reads of it.
//
// A hit copies the brick's pointer under one of 64 striped locks (held for a pointer copy); a miss
// takes one of 64 other striped locks, so two threads wanting the same brick decode it once, then
// reads it with pread and admits it. Eviction is CLOCK, a cheap LRU approximation: a hit sets the
// brick's reference bit, and the hand evicts bricks whose bit it finds clear until the decoded bytes
// are within the working budget: a quarter of the budget while each brick is read once, all of it
// once bricks are read again. A brick evicted while a reader still holds it lives on until that reader
// lets go (PagedVolume's pagers keep a few per thread), so the memory in use stays within the budget
// plus those few bricks per thread; and a miss on such a brick takes it back instead of decoding it
// again.
#include <array>
#include <atomic>
#include <cstdint>
#include <cstdlib>
#include <deque>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "engine/hierarchy/hierarchy.h"
#include "io/store/brick_pool.h"
#include "io/store/held_words.h"
#include "io/store/store_format.h"
#include "io/store/store_reader.h"

namespace isotope {

// Band 0's record words before they are computed (no record has them: their low half is a NaN code).
inline constexpr uint64_t kUnsetBounds = ~uint64_t{0};
inline constexpr uint32_t kUnsetInterval = ~uint32_t{0};
inline constexpr uint64_t kUnsetWeights = ~uint64_t{0};
inline constexpr uint16_t kUnsetSurplus = 0xffffu;

// A brick's values as the cache holds them: in one byte where the store's values are integers of
// 0..255 (a uint8 scan, 8-bit codes), two up to 65535 (uint16, 16-bit codes), else as floats
// (held_value_bytes), with 1 + 4 bytes a node for a uint8 brick's values and narrow bounds
// instead of 4 + 8: memory a paged extraction touches fresh, and more bricks within a cache's
// budget. A value read converts back to the very float it was.
class BrickValues {
 public:
  BrickValues(const void* data, int bytes) : data_(data), bytes_(bytes) {}
  int bytes() const { return bytes_; }  // per value: 1, 2 or 4
  const void* data() const { return data_; }
  // f(p) with p the values as held: const uint8_t*, const uint16_t* or const float*. For loops
  // over many values, which then read them without a test each.
  template <class F>
  decltype(auto) visit(F&& f) const {
    return of_width(bytes_, [&](auto held) { return f(static_cast<const decltype(held)*>(data_)); });
  }
  // f(T{}) with T the type values of `bytes` bytes are held in: uint8_t, uint16_t or float.
  template <class F>
  static decltype(auto) of_width(int bytes, F&& f) {
    if (bytes == 1) return f(uint8_t{});
    if (bytes == 2) return f(uint16_t{});
    return f(float{});
  }
  float operator[](size_t m) const {
    return visit([m](const auto* p) { return static_cast<float>(p[m]); });
  }

 private:
  const void* data_;
  int bytes_;
};

// One decoded brick. Arrays as the hierarchy's BrickView, but its values are a
// BrickValues, and its range-and-bound words are narrow (narrow_bounds) where its values are
// held in one byte; the arrays of fields not yet required are null.
class CachedBrick {
 public:
  int band() const { return band_; }
  // Its first node, in its band's grid units: a node's coordinates are this plus its Morton code's.
  const Box3& origin() const { return origin_; }
  BrickValues values() const { return {values_, value_bytes_}; }
  // The range-and-bound words: 32-bit where narrow(), else 64-bit; null for the other width.
  bool narrow() const { return held_bounds_bytes(value_bytes_) == 4; }
  uint32_t* narrow_bounds() const { return narrow() ? static_cast<uint32_t*>(bounds_) : nullptr; }
  uint64_t* bounds() const { return narrow() ? nullptr : static_cast<uint64_t*>(bounds_); }
  const void* bounds_at(uint32_t m) const {
    return static_cast<const char*>(bounds_) + size_t{m} * (narrow() ? sizeof(uint32_t) : sizeof(uint64_t));
  }
  uint16_t* surplus() const { return surplus_.load(std::memory_order_acquire); }
  uint32_t* exact() const { return exact_.load(std::memory_order_acquire); }
  uint32_t* paper() const { return paper_.load(std::memory_order_acquire); }
  uint64_t* weights() const { return weights_.load(std::memory_order_acquire); }
  // Whether the arrays of these fields are present (a published array is complete).
  bool has(const RecordFields& f) const {
    return (!f.exact || exact()) && (!f.weights || weights()) && (!f.paper || paper()) && (!f.surplus || surplus());
  }
  ~CachedBrick();

 private:
  friend class BrickCache;
  int band_ = 0;
  Box3 origin_{};
  const void* values_ = nullptr;
  int value_bytes_ = 4;
  void* bounds_ = nullptr;
  std::atomic<uint16_t*> surplus_{nullptr};
  std::atomic<uint32_t*> exact_{nullptr}, paper_{nullptr};
  std::atomic<uint64_t*> weights_{nullptr};
  std::mutex mutex_;  // while a section is decoded into it
  std::atomic<uint64_t> bytes_{0};
  std::shared_ptr<void> core_block_, values_block_;  // the core's arrays, from the cache's pools
  std::vector<std::unique_ptr<char[]>> extra_;       // the other fields' arrays
};

struct BrickCacheStats {
  int64_t bricks_read = 0;     // misses: bricks read, checked and decoded
  uint64_t bytes_read = 0;     // compressed bytes read, core and other sections
  int64_t hits = 0;            // lookups served from memory
  uint64_t peak_bytes = 0;     // most decoded bytes held at once
  int64_t slots = 0;           // bricks asked for or prefetched at least once: each has a slot
  uint64_t working_bytes = 0;  // what the cache keeps now: a quarter of the budget, or all of it
  // The store reader's, since it was opened (shared by every cache over it): reads that waited for
  // the disk, and read-ahead hints passed to the kernel (StoreReader::read_waits, read_hints).
  int64_t read_waits = 0;
  int64_t read_hints = 0;
};

class BrickCache {
 public:
  // Below kMinBricks bricks a traversal's working set (its region's bricks in a few bands) does
  // not fit and every step decodes again, so the budget is at least that many bricks.
  static constexpr uint64_t kMinBricks = 16;
  BrickCache(const StoreReader& store, uint64_t budget_bytes);
  BrickCache(const BrickCache&) = delete;
  BrickCache& operator=(const BrickCache&) = delete;

  // Brick `index` of the store's directory order with its core decoded. Thread-safe. Throws
  // IoError naming the brick when it cannot be read or is corrupt.
  std::shared_ptr<CachedBrick> get(int64_t index);
  // Makes the arrays of `fields` present in brick `index` (decoding their sections; band 0:
  // unset, to be filled by the reader). Thread-safe; throws as get().
  void require(CachedBrick& brick, int64_t index, const RecordFields& fields);
  // The caller will read again what it reads next (a triangle budget's search, then the
  // extraction at the eps it chose): the whole budget is kept from now on, without a window of
  // misses first (docs/METHOD.md, "working budget"). Thread-safe.
  void keep_whole_budget();
  // held_value_bytes of the store: one width for all bricks, so that one pool's freed blocks serve
  // every brick. A brick whose values do not fit is corrupt: get() throws IoError naming it.
  int value_bytes() const { return value_bytes_; }
  // A hint: brick `index` will be asked for soon. Starts the kernel reading it if it is not
  // resident (and was not asked for before), once hints pay.
  void prefetch(int64_t index);
  // Whether read-ahead hints pay: some read of the store has waited for the disk
  // (StoreReader::hints_pay). Until then prefetch() does nothing, not even make the brick's slot.
  bool hints_pay() const { return store_.hints_pay(); }

  const StoreReader& store() const { return store_; }
  uint64_t budget_bytes() const { return budget_; }  // as given, raised to kMinBricks bricks
  uint64_t brick_bytes() const;                      // a brick decoded whole, every field: the largest entry
  BrickCacheStats stats() const;

 private:
  // Tests make a cache that keeps no brick but those its readers hold, evicting all others on every
  // miss: what a reader must hold to stay correct is then tested, not left to a cache's timing.
  friend struct BrickCacheTesting;
  // brick and evicted are guarded by slot_locks_[index % kStripes]: held for a pointer copy only.
  // (std::atomic<std::shared_ptr> would do without them, but GCC 12's is not race-free by the
  // memory model: its load releases its internal lock with a relaxed store; ThreadSanitizer
  // reports it, google/sanitizers#1558.)
  struct Slot {
    std::shared_ptr<CachedBrick> brick;
    // After eviction: still alive while some reader holds it, and then taken back, not decoded
    // again (readers keep their recent bricks, so a small budget does not thrash on those).
    std::weak_ptr<CachedBrick> evicted;
    std::atomic<bool> referenced{false};
    std::atomic<bool> prefetched{false};
    bool decoded = false;  // once at least (under the brick's load lock): a miss now reads it again
  };
  // Brick `index`'s slot, made the first time the brick is asked for (thread-safe); find_slot
  // gives null until then.
  Slot& slot(int64_t index);
  Slot* find_slot(int64_t index) const;
  std::shared_ptr<CachedBrick> decode(int64_t index);
  std::shared_ptr<CachedBrick> resident(int64_t index);
  enum class Admitted { taken_back, first_read, read_again };  // from a reader, or decoded once or again
  void admit(int64_t index, uint64_t bytes, Admitted how);
  void evict_to_budget(int64_t keep);                            // under clock_mutex_; CLOCK, sparing brick `keep`
  void grow(int64_t index, CachedBrick& brick, uint64_t bytes);  // a brick took more memory

  const StoreReader& store_;
  const int value_bytes_;            // before budget_, whose floor it sizes
  const std::string value_refusal_;  // a brick's value the store's width does not hold (value_not_held)
  const uint64_t budget_;
  // The core's blocks, shared with the bricks: the bounds words, and the values in value_bytes_.
  struct Pools {
    Pools(size_t nodes, int value_bytes)
        : bounds(nodes * static_cast<size_t>(held_bounds_bytes(value_bytes))), values(nodes * value_bytes) {}
    BrickPool bounds, values;
  };
  std::shared_ptr<Pools> pools_;
  // A slot per brick asked for, reached through a table of a pointer per brick of the store. A
  // store has hundreds of thousands of bricks (millions at 2048^3) and a coarse extraction asks
  // for a few thousand: a slot for each, made up front, was 40 bytes a brick to touch before the
  // first brick was read (13 MB at 1024^3, 100 MB at 2048^3). The table is zero-filled memory
  // that the kernel maps only where it is touched, read and written through std::atomic_ref.
  struct FreeTable {
    void operator()(Slot** p) const { std::free(p); }
  };
  std::unique_ptr<Slot*[], FreeTable> slot_table_;
  mutable std::mutex slots_mutex_;  // taken when a slot is made
  std::deque<Slot> slots_;          // never moves a slot
  static constexpr size_t kStripes = 64;
  std::mutex slot_locks_[kStripes];  // short: a pointer copy
  // Long: one brick's read and decode, so that it is done once. Many stripes, since a thread that
  // wants another brick of a busy stripe waits that whole decode: with 64, one decode in 80
  // waited so on two threads.
  static constexpr size_t kLoadStripes = 1024;
  std::mutex load_locks_[kLoadStripes];
  mutable std::mutex clock_mutex_;  // the resident list and the hand; taken on misses only
  std::vector<int64_t> resident_;
  size_t hand_ = 0;
  uint64_t resident_bytes_ = 0, peak_bytes_ = 0;
  // The bytes the cache keeps: a quarter of the budget until a window of misses finds too many
  // bricks read again, then all of it (docs/METHOD.md, "working budget").
  uint64_t working_ = 0;
  int64_t window_misses_ = 0, window_again_ = 0;
  std::atomic<int64_t> hits_{0}, bricks_read_{0};
  std::atomic<uint64_t> bytes_read_{0};
};

}  // namespace isotope
