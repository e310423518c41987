#pragma once
// Grid edge -> mesh vertex index, the welding table of marching tetrahedra.
// Why our own: the keys are non-zero 64-bit integers (so 0 marks a free slot), entries are
// never erased, and it sits in the innermost loop. Linear probing over one flat array, no
// per-entry allocation. (Slots taken straight from the brick-ordered keys were tried: they
// cluster, and extraction got 20% slower than with this multiplicative hash.)
#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "isotope/detail/huge_page_allocator.h"

namespace isotope {

class EdgeVertexMap {
 public:
  static constexpr uint32_t kAbsent = 0xffffffffu;

  explicit EdgeVertexMap(size_t expected = 1024) { rehash(capacity_for(expected)); }

  // Empty again, keeping the table's size: a table reused this way is memory already touched.
  void clear() {
    std::fill(keys_.begin(), keys_.end(), uint64_t{0});
    size_ = 0;
  }

  // Returns the index stored for key, or stores `fresh` and returns kAbsent.
  uint32_t find_or_insert(uint64_t key, uint32_t fresh) {
    if (2 * (size_ + 1) > keys_.size()) rehash(keys_.size() * 2);
    for (size_t i = slot(key);; i = (i + 1) & mask_) {
      if (keys_[i] == key) return values_[i];
      if (keys_[i] == 0) {
        keys_[i] = key;
        values_[i] = fresh;
        ++size_;
        return kAbsent;
      }
    }
  }

 private:
  static size_t capacity_for(size_t n) {
    size_t c = 16;
    while (c < 2 * n) c *= 2;
    return c;
  }
  size_t slot(uint64_t key) const { return static_cast<size_t>((key * 0x9E3779B97F4A7C15ull) >> 20) & mask_; }
  void rehash(size_t capacity) {
    Keys old_keys(capacity, 0);
    Values old_values(capacity);
    old_keys.swap(keys_);
    old_values.swap(values_);
    mask_ = capacity - 1;
    size_ = 0;
    for (size_t i = 0; i < old_keys.size(); ++i)
      if (old_keys[i] != 0) find_or_insert(old_keys[i], old_values[i]);
  }

  using Keys = std::vector<uint64_t, detail::HugePageAllocator<uint64_t>>;
  using Values = std::vector<uint32_t, detail::HugePageAllocator<uint32_t>>;
  Keys keys_;
  Values values_;
  size_t mask_ = 0, size_ = 0;
};

}  // namespace isotope
