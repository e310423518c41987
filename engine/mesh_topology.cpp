#include "engine/mesh_topology.h"

#include <algorithm>
#include <numeric>
#include <vector>

namespace isotope {

MeshTopology measure_topology(const Mesh& mesh) {
  MeshTopology t;
  t.triangles = static_cast<int64_t>(mesh.triangles.size());
  std::vector<uint64_t> edges;
  edges.reserve(mesh.triangles.size() * 3);
  std::vector<uint32_t> parent(mesh.positions.size());
  std::iota(parent.begin(), parent.end(), 0u);
  auto find = [&](uint32_t x) {
    while (parent[x] != x) x = parent[x] = parent[parent[x]];
    return x;
  };
  std::vector<uint8_t> used(mesh.positions.size(), 0);
  for (const auto& tri : mesh.triangles)
    for (int i = 0; i < 3; ++i) {
      const uint32_t a = tri[i], b = tri[(i + 1) % 3];
      used[a] = 1;
      edges.push_back(uint64_t{std::min(a, b)} << 32 | std::max(a, b));
      const uint32_t ra = find(a), rb = find(b);
      if (ra != rb) parent[ra] = rb;
    }
  std::sort(edges.begin(), edges.end());
  for (size_t i = 0; i < edges.size();) {
    size_t j = i;
    while (j < edges.size() && edges[j] == edges[i]) ++j;
    ++t.edges;
    if (j - i == 1) ++t.boundary_edges;
    if (j - i > 2) ++t.nonmanifold_edges;
    i = j;
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
