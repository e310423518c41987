#pragma once
// A mesh's undirected edges filed under their lower vertex, and its components through shared
// edges, built on all threads: what the topology measure (the summary line) and the component
// report count from, each edge found once.
#include <cstddef>
#include <cstdint>
#include <vector>

#include "isotope/mesh.h"

namespace isotope {

// OFFSET: the type of the offsets into `upper`, 32 bits where the mesh's 3F edge ends fit (half
// the memory traffic of the filing passes' counters, a quarter of their time), 64 beyond.
template <class Offset>
struct FiledEdges {
  // Vertex v's edges (v, w), w > v, are the distinct values w of upper[first[v] .. first[v + 1]),
  // sorted, each held by as many triangles as it appears times there.
  std::vector<Offset> first;
  std::vector<uint32_t> upper;
  std::vector<uint8_t> used;   // per vertex: 1 when a triangle holds it
  std::vector<uint32_t> root;  // per vertex: the lowest vertex of its component (itself when lowest)
  // Distinct edges, and of them those one triangle holds and those three or more hold: counted
  // as they are filed.
  int64_t edges = 0, boundary_edges = 0, nonmanifold_edges = 0;
};

// Triangles must refer to vertices of MESH (the caller checks, or made the mesh). Offset:
// uint32_t (when 3F < 2^32) or uint64_t.
template <class Offset>
FiledEdges<Offset> file_edges(const Mesh& mesh);

// f(file_edges<Offset>(mesh)) with the narrowest offsets that hold the mesh's edge ends.
template <class F>
decltype(auto) with_filed_edges(const Mesh& mesh, F&& f) {
  if (3 * mesh.triangles.size() < (size_t{1} << 32)) return f(file_edges<uint32_t>(mesh));
  return f(file_edges<uint64_t>(mesh));
}

// Calls f(w, n) for each run of n equal values w of the sorted [begin, end).
template <class F>
void for_each_run(const uint32_t* begin, const uint32_t* end, F&& f) {
  for (const uint32_t* i = begin; i != end;) {
    const uint32_t* j = i + 1;
    while (j != end && *j == *i) ++j;
    f(*i, j - i);
    i = j;
  }
}

// Calls f(w, triangles) for each edge (v, w) of vertex v.
template <class Offset, class F>
void for_each_edge_of(const FiledEdges<Offset>& e, size_t v, F&& f) {
  for_each_run(e.upper.data() + e.first[v], e.upper.data() + e.first[v + 1], f);
}

}  // namespace isotope
