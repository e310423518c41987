#include "engine/mesh_topology.h"

#include <algorithm>
#include <numeric>
#include <vector>

namespace isotope {

MeshTopology measure_topology(const Mesh& mesh) {
  MeshTopology t;
  t.triangles = static_cast<int64_t>(mesh.triangles.size());
  const size_t n = mesh.positions.size();
  std::vector<uint32_t> parent(n);
  std::iota(parent.begin(), parent.end(), 0u);
  auto find = [&](uint32_t x) {
    while (parent[x] != x) x = parent[x] = parent[parent[x]];
    return x;
  };
  // Each undirected edge is filed under its lower vertex (counting pass, then filling): a vertex's
  // few entries are then sorted in place, where one sort of all 3F edges took most of the time
  // (20 ms of a 100k-triangle mesh that `isotope serve` answers interactively).
  std::vector<uint32_t> first(n + 1, 0);
  for (const auto& tri : mesh.triangles)
    for (int i = 0; i < 3; ++i) ++first[std::min(tri[i], tri[(i + 1) % 3]) + 1];
  std::partial_sum(first.begin(), first.end(), first.begin());
  std::vector<uint32_t> upper(first.back()), fill(first.begin(), first.end() - 1);
  std::vector<uint8_t> used(n, 0);
  for (const auto& tri : mesh.triangles)
    for (int i = 0; i < 3; ++i) {
      const uint32_t a = tri[i], b = tri[(i + 1) % 3];
      used[a] = 1;
      upper[fill[std::min(a, b)]++] = std::max(a, b);
      const uint32_t ra = find(a), rb = find(b);
      if (ra != rb) parent[ra] = rb;
    }
  for (size_t v = 0; v < n; ++v) {
    const auto begin = upper.begin() + first[v], end = upper.begin() + first[v + 1];
    std::sort(begin, end);
    for (auto i = begin; i != end;) {
      const auto j = std::find_if(i, end, [&](uint32_t w) { return w != *i; });
      ++t.edges;
      if (j - i == 1) ++t.boundary_edges;
      if (j - i > 2) ++t.nonmanifold_edges;
      i = j;
    }
  }
  for (uint32_t v = 0; v < used.size(); ++v) {
    if (!used[v]) continue;
    ++t.vertices;
    if (find(v) == v) ++t.components;
  }
  t.euler_characteristic = t.vertices - t.edges + t.triangles;
  return t;
}

}  // namespace isotope
