#include <algorithm>
#include <vector>

#include "engine/core/parallel.h"
#include "engine/topology/filed_edges.h"
#include "isotope/mesh.h"

namespace isotope {

MeshTopology measure_topology(const Mesh& mesh) {
  return with_filed_edges(mesh, [&](const auto& e) {
    MeshTopology t;
    t.triangles = static_cast<int64_t>(mesh.triangles.size());
    t.edges = e.edges;
    t.boundary_edges = e.boundary_edges;
    t.nonmanifold_edges = e.nonmanifold_edges;
    for (size_t v = 0; v < e.used.size(); ++v)
      if (e.used[v]) {
        ++t.vertices;
        t.components += e.root[v] == v;
      }
    t.euler_characteristic = t.vertices - t.edges + t.triangles;
    return t;
  });
}

}  // namespace isotope
