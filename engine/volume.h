#pragma once
// A scalar volume held in memory: nodes on a regular grid, x fastest, then y, then z.
#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

namespace isotope {

struct Volume {
  std::array<int64_t, 3> dims{0, 0, 0};     // nodes per axis (x, y, z)
  std::array<double, 3> spacing{1, 1, 1};   // physical distance between nodes
  std::array<double, 3> origin{0, 0, 0};    // physical position of node (0,0,0)
  std::vector<float> values;                // dims[0]*dims[1]*dims[2], x fastest

  int64_t node_count() const { return dims[0] * dims[1] * dims[2]; }
  size_t index(int64_t x, int64_t y, int64_t z) const {
    return static_cast<size_t>((z * dims[1] + y) * dims[0] + x);
  }
  float at(int64_t x, int64_t y, int64_t z) const { return values[index(x, y, z)]; }
};

}  // namespace isotope
