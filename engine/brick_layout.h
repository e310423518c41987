#pragma once
// Where a lattice node's value and record live in memory: in 8^3 bricks. A subtree of the
// traversal covers a compact region, so the records it reads share cache lines and pages;
// with x-fastest rows, z-neighbours would lie side^2 entries apart.
#include <cstdint>

namespace isotope {

struct BrickLayout {
  static constexpr int kBits = 3;
  static constexpr int64_t kMask = (1 << kBits) - 1;

  int64_t bricks_x = 0, bricks_y = 0, size = 0;

  BrickLayout() = default;
  explicit BrickLayout(int64_t side) {
    const int64_t b = (side + kMask) >> kBits;
    bricks_x = bricks_y = b;
    size = b * b * b << (3 * kBits);
  }
  int64_t slot(int64_t x, int64_t y, int64_t z) const {
    const int64_t brick = ((z >> kBits) * bricks_y + (y >> kBits)) * bricks_x + (x >> kBits);
    return brick << (3 * kBits) | (z & kMask) << (2 * kBits) | (y & kMask) << kBits | (x & kMask);
  }
};

}  // namespace isotope
