#include "engine/hierarchy/critical_table.h"

#include <array>
#include <cstddef>
#include <numeric>
#include <vector>

namespace isotope {
namespace {

int find(std::array<int, 10>& parent, int x) {
  while (parent[x] != x) x = parent[x] = parent[parent[x]];
  return x;
}

int count_components(int ring, uint32_t pattern) {
  std::array<int, 10> parent;
  std::iota(parent.begin(), parent.end(), 0);
  const int nodes = ring + 2;
  int components = nodes;
  auto join = [&](int u, int w) {
    if (((pattern >> u) & 1u) != ((pattern >> w) & 1u)) return;  // step 2: '+'/'-' edges go
    const int ru = find(parent, u), rw = find(parent, w);
    if (ru != rw) {
      parent[ru] = rw;
      --components;
    }
  };
  for (int i = 0; i < ring; ++i) {  // step 1: the polyhedron's edges
    join(0, 2 + i);
    join(1, 2 + i);
    join(2 + i, 2 + (i + 1) % ring);
  }
  return components;
}

struct Tables {
  std::array<std::vector<uint8_t>, 3> critical;
  Tables() {
    for (int t = 0; t < 3; ++t) {
      const int ring = ring_size(static_cast<PolyhedronType>(t));
      critical[t].resize(size_t{1} << (ring + 2));
      for (uint32_t p = 0; p < critical[t].size(); ++p) {
        const int c = count_components(ring, p);
        critical[t][p] = (c == 1 || c > 2) ? 1 : 0;  // steps 3 and 4
      }
    }
  }
};

const Tables& tables() {
  static const Tables t;
  return t;
}

}  // namespace

bool is_critical_pattern(PolyhedronType type, uint32_t pattern) {
  return tables().critical[static_cast<int>(type)][pattern] != 0;
}

int critical_pattern_count(PolyhedronType type) {
  int n = 0;
  for (uint8_t c : tables().critical[static_cast<int>(type)]) n += c;
  return n;
}

int pattern_components(PolyhedronType type, uint32_t pattern) { return count_components(ring_size(type), pattern); }

}  // namespace isotope
