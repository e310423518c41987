#pragma once
// The (2^k+1)^3 node lattice the hierarchy lives on, and the smallest one that holds a volume.
#include <array>
#include <cstdint>

namespace isotope {

using Coord = std::array<int64_t, 3>;

struct Lattice {
  int k = 0;         // levels of the hierarchy: 0 .. 3k
  int64_t n = 1;     // 2^k cells per axis
  int64_t side = 2;  // n + 1 nodes per axis

  static Lattice enclosing(const std::array<int64_t, 3>& dims);  // smallest with n >= max(dims) - 1
  int max_level() const { return 3 * k; }
  int64_t node_count() const { return side * side * side; }
  int64_t index(const Coord& c) const { return (c[2] * side + c[1]) * side + c[0]; }
  int64_t index(int64_t x, int64_t y, int64_t z) const { return (z * side + y) * side + x; }
  Coord coord(int64_t i) const { return {i % side, (i / side) % side, i / (side * side)}; }
  bool contains(const Coord& c) const {
    return c[0] >= 0 && c[1] >= 0 && c[2] >= 0 && c[0] <= n && c[1] <= n && c[2] <= n;
  }
};

inline Lattice Lattice::enclosing(const std::array<int64_t, 3>& dims) {
  int64_t need = 1;
  for (int64_t d : dims) need = d - 1 > need ? d - 1 : need;
  Lattice l;
  while (l.n < need) {
    l.n *= 2;
    ++l.k;
  }
  l.side = l.n + 1;
  return l;
}

}  // namespace isotope
