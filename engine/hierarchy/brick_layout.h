#pragma once
// Where a node's value or record lives in memory: in 8^3 bricks. A subtree of the traversal
// covers a compact region, so the records it reads share cache lines and pages; with
// x-fastest rows, z-neighbours would lie a whole slice apart.
#include <array>
#include <cstdint>

namespace isotope {

struct BrickLayout {
  static constexpr int kBits = 3;
  static constexpr int64_t kMask = (1 << kBits) - 1;

  int64_t bricks_x = 0, bricks_y = 0, size = 0;

  BrickLayout() = default;
  // nodes: nodes per axis to hold, coordinates 0 .. nodes-1.
  explicit BrickLayout(const std::array<int64_t, 3>& nodes) {
    bricks_x = (nodes[0] + kMask) >> kBits;
    bricks_y = (nodes[1] + kMask) >> kBits;
    size = bricks_x * bricks_y * ((nodes[2] + kMask) >> kBits) << (3 * kBits);
  }
  int64_t slot(int64_t x, int64_t y, int64_t z) const {
    const int64_t brick = ((z >> kBits) * bricks_y + (y >> kBits)) * bricks_x + (x >> kBits);
    return brick << (3 * kBits) | (z & kMask) << (2 * kBits) | (y & kMask) << kBits | (x & kMask);
  }
};

}  // namespace isotope
