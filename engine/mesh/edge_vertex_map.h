#pragma once
// Grid edge -> mesh vertex index, the welding table of marching tetrahedra.
// Why our own: the keys are 64-bit integers, entries are never erased, and it sits in the
// innermost loop. Linear probing over one flat array of slots, each holding its key and its
// value together (one cache line per probe, where separate arrays of keys and values cost two
// misses on every new vertex), no per-entry allocation. (Slots taken straight from the
// brick-ordered keys were tried: they cluster, and extraction got 20% slower than with this
// multiplicative hash.)
#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "engine/core/huge_blocks.h"

namespace isotope {

class EdgeVertexMap {
 public:
  static constexpr uint32_t kAbsent = 0xffffffffu;

  explicit EdgeVertexMap(size_t expected = 1024) { rehash(capacity_for(expected)); }

  // Empty again, in O(1), keeping the table's memory: a slot is taken only while it carries the
  // table's current stamp, so a new stamp frees them all. The next mesh starts on the table's first
  // kStartSlots slots and grows over the rest as it needs: a table lent from one mesh to the next
  // this way is memory already touched, and a small mesh after a large one keeps to a few cache-warm
  // pages instead of scattering its keys over the large one's table.
  void clear() { empty_spanning(kStartSlots); }

  // Empty again, in O(1), spanning the slots the last mesh needed (at least kStartSlots; as it was
  // when that mesh was empty): for a mesh about as large as the last (the next slab of a
  // full-resolution march), which from kStartSlots grew through every doubling again, each rehash
  // inserting what it held anew. Sized by the last mesh, not the largest ever: a builder lent to a
  // small extraction after a large one keeps to a small span, as clear() does.
  void clear_at_size() { empty_spanning(size_ > 0 ? std::max(kStartSlots, capacity_for(size_)) : mask_ + 1); }

  // The memory the table holds, taken or not.
  size_t bytes() const { return (slots_.capacity() + moving_.capacity()) * sizeof(Slot); }

  // Returns the index stored for key, or stores `fresh` and returns kAbsent.
  uint32_t find_or_insert(uint64_t key, uint32_t fresh) {
    if (2 * (size_ + 1) > mask_ + 1) rehash(2 * (mask_ + 1));
    for (size_t i = slot(key);; i = (i + 1) & mask_) {
      Slot& s = slots_[i];
      if (s.stamp != stamp_) {
        s = {key, fresh, stamp_};
        ++size_;
        return kAbsent;
      }
      if (s.key == key) return s.value;
    }
  }

 private:
  struct Slot {
    uint64_t key;
    uint32_t value;
    uint32_t stamp;  // taken while it equals the table's stamp_
  };
  static constexpr size_t kStartSlots = 4096;  // 64 KB
  static size_t capacity_for(size_t n) {
    size_t c = 16;
    while (c < 2 * n) c *= 2;
    return c;
  }
  // Empty, over the first `span` slots (at most all there are).
  void empty_spanning(size_t span) {
    next_stamp();
    size_ = 0;
    mask_ = std::min(slots_.size(), span) - 1;
  }
  size_t slot(uint64_t key) const { return static_cast<size_t>((key * 0x9E3779B97F4A7C15ull) >> 20) & mask_; }
  void next_stamp() {
    if (++stamp_ == 0) {  // the stamps wrapped: no slot may look taken
      for (Slot& s : slots_) s.stamp = 0;
      stamp_ = 1;
    }
  }
  // Over the first `capacity` slots, allocated if need be; what was taken is inserted again.
  void rehash(size_t capacity) {
    moving_.clear();
    for (size_t i = 0; i <= mask_ && i < slots_.size(); ++i)
      if (slots_[i].stamp == stamp_) moving_.push_back(slots_[i]);
    if (capacity > slots_.size()) {
      // Faulted in by one call before the zero-fill writes it: a table grows to megabytes of
      // fresh memory, whose pages faulted one by one in the fill cost more than the march of a
      // slab's first layers (docs/METHOD.md, "Fresh memory").
      Slots grown;
      detail::resize_prefaulted(grown, capacity);  // Slot{0, 0, 0}: free under any stamp
      grown.swap(slots_);
      stamp_ = 1;
    } else {
      next_stamp();
    }
    mask_ = capacity - 1;
    size_ = 0;
    for (const Slot& s : moving_) find_or_insert(s.key, s.value);
  }

  using Slots = std::vector<Slot, detail::HugePageAllocator<Slot>>;
  Slots slots_;
  std::vector<Slot> moving_;  // what a rehash inserts again
  uint32_t stamp_ = 1;
  size_t mask_ = 0, size_ = 0;
};

}  // namespace isotope
