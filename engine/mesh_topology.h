#pragma once
// Combinatorial measures of a triangle mesh: what "same topology" is checked against.
#include <cstdint>

#include "engine/mesh.h"

namespace isotope {

struct MeshTopology {
  int64_t vertices = 0;           // vertices referenced by at least one triangle
  int64_t triangles = 0;
  int64_t edges = 0;              // distinct undirected edges
  int64_t components = 0;         // connected through shared vertices
  int64_t euler_characteristic = 0;  // V - E + F
  int64_t boundary_edges = 0;     // edges with one incident triangle
  int64_t nonmanifold_edges = 0;  // edges with three or more
};

MeshTopology measure_topology(const Mesh& mesh);

}  // namespace isotope
