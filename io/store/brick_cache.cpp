#include "io/store/brick_cache.h"

#include <algorithm>
#include <new>
#include <string>

#include "isotope/error.h"

namespace isotope {
namespace {

// A brick's core as the cache holds it: its values and its range-and-bound words.
size_t core_bytes(const StoreLayout& layout, int value_bytes) {
  return static_cast<size_t>(layout.brick_nodes()) * static_cast<size_t>(value_bytes + held_bounds_bytes(value_bytes));
}

template <class T>
T* new_array(std::vector<std::unique_ptr<char[]>>& owner, int64_t n, T fill) {
  owner.push_back(std::make_unique_for_overwrite<char[]>(static_cast<size_t>(n) * sizeof(T)));
  T* p = reinterpret_cast<T*>(owner.back().get());
  std::fill_n(p, n, fill);
  return p;
}

}  // namespace

CachedBrick::~CachedBrick() = default;

BrickCache::BrickCache(const StoreReader& store, uint64_t budget_bytes)
    : store_(store),
      value_bytes_(held_value_bytes(store.header())),
      value_refusal_(value_not_held(store.header())),
      budget_(std::max<uint64_t>(budget_bytes, kMinBricks * core_bytes(store.layout(), value_bytes_))),
      pools_(std::make_shared<Pools>(static_cast<size_t>(store.layout().brick_nodes()), value_bytes_)),
      slot_table_(static_cast<Slot**>(std::calloc(static_cast<size_t>(store.layout().brick_count()), sizeof(Slot*)))) {
  if (!slot_table_) throw std::bad_alloc();
  // The working budget starts at a quarter (at least kMinBricks bricks, at most the budget).
  working_ = std::max<uint64_t>(budget_ / 4,
                                std::min<uint64_t>(budget_, kMinBricks * core_bytes(store.layout(), value_bytes_)));
}

BrickCache::Slot& BrickCache::slot(int64_t index) {
  if (Slot* s = find_slot(index)) return *s;
  const std::lock_guard<std::mutex> lock(slots_mutex_);
  std::atomic_ref<Slot*> entry(slot_table_[static_cast<size_t>(index)]);
  if (Slot* s = entry.load(std::memory_order_relaxed)) return *s;  // made meanwhile
  Slot* s = &slots_.emplace_back();
  entry.store(s, std::memory_order_release);
  return *s;
}

BrickCache::Slot* BrickCache::find_slot(int64_t index) const {
  return std::atomic_ref<Slot*>(slot_table_[static_cast<size_t>(index)]).load(std::memory_order_acquire);
}

uint64_t BrickCache::brick_bytes() const {
  // The core, then surplus, exact and paper intervals, weights.
  return static_cast<uint64_t>(store_.layout().brick_nodes()) *
         static_cast<uint64_t>(value_bytes_ + held_bounds_bytes(value_bytes_) + 2 + 4 + 4 + 8);
}

std::shared_ptr<CachedBrick> BrickCache::decode(int64_t index) {
  const StoreLayout& layout = store_.layout();
  auto b = std::make_shared<CachedBrick>();
  const auto [band, brick] = store_.locate_brick(index);
  b->band_ = band;
  for (int a = 0; a < 3; ++a) b->origin_[static_cast<size_t>(a)] = brick[static_cast<size_t>(a)] * layout.brick_width();
  const auto nodes = static_cast<size_t>(layout.brick_nodes());
  std::shared_ptr<Pools> pools = pools_;
  // Decoded in place where values are floats or bytes (a one-byte store's words checked as they are
  // narrowed, its values as they are made bytes); two-byte values go through an array of this
  // thread's, checked to fit, then copied in.
  std::shared_ptr<void> bounds(pools->bounds.allocate(), [pools](void* p) { pools->bounds.release(p); });
  std::shared_ptr<void> kept(pools->values.allocate(), [pools](void* p) { pools->values.release(p); });
  thread_local std::vector<float> wide;
  float* values = static_cast<float*>(kept.get());
  if (value_bytes_ == 2) {
    wide.resize(nodes);
    values = wide.data();
  }
  const bool narrow = value_bytes_ == 1, records = stores_records(layout, b->band_);
  const NarrowBrick one_byte{static_cast<uint8_t*>(kept.get()), static_cast<uint32_t*>(bounds.get()), value_refusal_};
  const BrickView view{narrow ? nullptr : values,
                       narrow ? nullptr : static_cast<uint64_t*>(bounds.get()),
                       nullptr,
                       nullptr,
                       nullptr,
                       nullptr};
  const uint64_t read = store_.read_brick(index, {true, false, false, false}, view, narrow ? nullptr : values,
                                          narrow ? &one_byte : nullptr);
  bytes_read_.fetch_add(read, std::memory_order_relaxed);
  if (value_bytes_ == 2) {
    if (fewest_bytes(wide) > value_bytes_)
      throw IoError(store_.describe_brick(index) + ": " + value_refusal_ + " (corrupt brick)");
    std::copy(wide.begin(), wide.end(), static_cast<uint16_t*>(kept.get()));
  }
  b->bounds_ = bounds.get();
  b->values_ = kept.get();
  b->value_bytes_ = value_bytes_;
  b->bytes_ = pools->bounds.block_bytes() + pools->values.block_bytes();
  b->core_block_ = std::move(bounds);
  b->values_block_ = std::move(kept);
  if (!records) {  // band 0: filled on first read; the corners: none
    if (narrow)
      std::fill_n(b->narrow_bounds(), nodes, b->band_ == 0 ? kUnsetNarrowBounds : 0);
    else
      std::fill_n(b->bounds(), nodes, b->band_ == 0 ? kUnsetBounds : 0);
  }
  return b;
}

void BrickCache::require(CachedBrick& brick, int64_t index, const RecordFields& fields) {
  if (brick.has(fields)) return;
  const std::lock_guard<std::mutex> lock(brick.mutex_);
  const StoreLayout& layout = store_.layout();
  const int64_t n = layout.brick_nodes();
  const bool stored = stores_records(layout, brick.band_);
  const bool band0 = brick.band_ == 0;
  // Arrays for the sections needed and missing; the extra section holds paper and surplus.
  StoreSections which{false, false, false, false};
  uint16_t* surplus = brick.surplus();
  uint32_t *exact = brick.exact(), *paper = brick.paper();
  uint64_t* weights = brick.weights();
  const uint64_t before = static_cast<uint64_t>(brick.extra_.size());
  uint64_t added = 0;
  if (fields.exact && !exact) {
    exact = new_array<uint32_t>(brick.extra_, n, band0 ? kUnsetInterval : 0);
    which[static_cast<size_t>(Section::exact)] = true;
    added += n * 4;
  }
  if (fields.weights && !weights) {
    weights = new_array<uint64_t>(brick.extra_, n, band0 ? kUnsetWeights : 0);
    which[static_cast<size_t>(Section::weights)] = true;
    added += n * 8;
  }
  if ((fields.paper || fields.surplus) && !(paper && surplus)) {
    paper = new_array<uint32_t>(brick.extra_, n, band0 ? kUnsetInterval : 0);
    surplus = new_array<uint16_t>(brick.extra_, n, band0 ? kUnsetSurplus : 0);
    which[static_cast<size_t>(Section::extra)] = true;
    added += n * 6;
  }
  if (brick.extra_.size() == before) return;
  if (stored) {
    // The values were decoded with the core; the sections here do not touch them.
    const BrickView view{nullptr, nullptr, surplus, exact, paper, weights};  // the core is decoded
    const uint64_t read = store_.read_brick(index, which, view, nullptr);
    bytes_read_.fetch_add(read, std::memory_order_relaxed);
  }
  if (which[static_cast<size_t>(Section::exact)]) brick.exact_.store(exact, std::memory_order_release);
  if (which[static_cast<size_t>(Section::weights)]) brick.weights_.store(weights, std::memory_order_release);
  if (which[static_cast<size_t>(Section::extra)]) {
    brick.paper_.store(paper, std::memory_order_release);
    brick.surplus_.store(surplus, std::memory_order_release);
  }
  grow(index, brick, added);
}

void BrickCache::prefetch(int64_t index) {
  if (!hints_pay()) return;
  Slot& s = slot(index);
  if (s.prefetched.load(std::memory_order_relaxed)) return;
  s.prefetched.store(true, std::memory_order_relaxed);
  if (resident(index)) return;
  store_.prefetch(index, {true, false, false, false});
}

std::shared_ptr<CachedBrick> BrickCache::resident(int64_t index) {
  const Slot* s = find_slot(index);
  if (!s) return nullptr;
  const std::lock_guard<std::mutex> lock(slot_locks_[static_cast<size_t>(index) % kStripes]);
  return s->brick;
}

std::shared_ptr<CachedBrick> BrickCache::get(int64_t index) {
  Slot& slot = this->slot(index);
  auto found = resident(index);
  if (!found) {
    const std::lock_guard<std::mutex> lock(load_locks_[static_cast<size_t>(index) % kLoadStripes]);
    found = resident(index);  // another thread may have loaded it meanwhile
    if (!found) {
      {  // evicted, but still held by a reader?
        const std::lock_guard<std::mutex> slot_lock(slot_locks_[static_cast<size_t>(index) % kStripes]);
        found = slot.evicted.lock();
      }
      const bool fresh = !found;
      bool again = false;
      if (fresh) {
        found = decode(index);
        bricks_read_.fetch_add(1, std::memory_order_relaxed);
        again = slot.decoded;
        slot.decoded = true;
      }
      {
        const std::lock_guard<std::mutex> slot_lock(slot_locks_[static_cast<size_t>(index) % kStripes]);
        slot.brick = found;
      }
      slot.referenced.store(true, std::memory_order_relaxed);
      admit(index, found->bytes_.load(std::memory_order_relaxed),
            !fresh  ? Admitted::taken_back
            : again ? Admitted::read_again
                    : Admitted::first_read);
      if (fresh) return found;
    }
  }
  hits_.fetch_add(1, std::memory_order_relaxed);
  if (!slot.referenced.load(std::memory_order_relaxed)) slot.referenced.store(true, std::memory_order_relaxed);
  return found;
}

void BrickCache::grow(int64_t index, CachedBrick& brick, uint64_t bytes) {
  // Under the clock's lock, as eviction: an evicted brick counts again only when taken back.
  const std::lock_guard<std::mutex> lock(clock_mutex_);
  brick.bytes_.fetch_add(bytes, std::memory_order_relaxed);
  bool is_resident = false;
  {
    const std::lock_guard<std::mutex> slot_lock(slot_locks_[static_cast<size_t>(index) % kStripes]);
    const Slot* s = find_slot(index);
    is_resident = s && s->brick.get() == &brick;
  }
  if (!is_resident) return;
  resident_bytes_ += bytes;
  peak_bytes_ = std::max(peak_bytes_, resident_bytes_);
  evict_to_budget(index);
}

void BrickCache::keep_whole_budget() {
  const std::lock_guard<std::mutex> lock(clock_mutex_);
  working_ = budget_;
}

void BrickCache::admit(int64_t index, uint64_t bytes, Admitted how) {
  const std::lock_guard<std::mutex> lock(clock_mutex_);
  if (how != Admitted::taken_back) {  // a miss: is the cache reading bricks again, i.e. would keeping more pay?
    constexpr int64_t kWindow = 512;
    ++window_misses_, window_again_ += how == Admitted::read_again;
    if (window_misses_ == kWindow) {
      if (window_again_ * 4 > window_misses_) working_ = budget_;
      window_misses_ = window_again_ = 0;
    }
  }
  resident_.push_back(index);
  resident_bytes_ += bytes;
  peak_bytes_ = std::max(peak_bytes_, resident_bytes_);
  evict_to_budget(index);
}

void BrickCache::evict_to_budget(int64_t index) {
  while (resident_bytes_ > working_ && resident_.size() > 1) {
    if (hand_ >= resident_.size()) hand_ = 0;
    const int64_t victim = resident_[hand_];
    Slot& slot = *find_slot(victim);  // resident, so made
    if (victim == index || slot.referenced.exchange(false, std::memory_order_relaxed)) {
      ++hand_;  // a second chance
      continue;
    }
    uint64_t freed = 0;
    {
      const std::lock_guard<std::mutex> slot_lock(slot_locks_[static_cast<size_t>(victim) % kStripes]);
      freed = slot.brick->bytes_.load(std::memory_order_relaxed);
      slot.evicted = slot.brick;
      slot.brick.reset();
      slot.prefetched.store(false, std::memory_order_relaxed);
    }
    resident_bytes_ -= std::min(freed, resident_bytes_);
    resident_[hand_] = resident_.back();
    resident_.pop_back();
  }
}

BrickCacheStats BrickCache::stats() const {
  BrickCacheStats s;
  s.bricks_read = bricks_read_.load();
  s.bytes_read = bytes_read_.load();
  s.hits = hits_.load();
  s.read_waits = store_.read_waits();
  s.read_hints = store_.read_hints();
  {
    const std::lock_guard<std::mutex> lock(slots_mutex_);
    s.slots = static_cast<int64_t>(slots_.size());
  }
  const std::lock_guard<std::mutex> lock(clock_mutex_);
  s.peak_bytes = peak_bytes_;
  s.working_bytes = working_;
  return s;
}

}  // namespace isotope
