#pragma once
// A mesh's vertices split into parts of consecutive indices, and for each part the triangles it
// must read: what lets a pass that writes per vertex (the topology's edge filing, the vertex
// normals) run on all threads with no two writing one vertex and no locked add, each part reading
// little more than its share of the triangles.
#include <algorithm>
#include <array>
#include <cstddef>
#include <cstdint>
#include <utility>
#include <vector>

#include "isotope/mesh.h"

namespace isotope {

// Triangles per chunk, the unit a part reads and a parallel task: enough to pay for a task, few
// enough to balance two threads on a mesh of a few hundred thousand triangles (what `isotope serve`
// measures per request).
inline constexpr size_t kTrianglesPerChunk = size_t{1} << 15;

inline int64_t chunks_of(size_t triangles) {
  return static_cast<int64_t>((triangles + kTrianglesPerChunk - 1) / kTrianglesPerChunk);
}

// Chunk k's triangles, [begin, end), of COUNT.
inline std::pair<size_t, size_t> chunk_triangles(int64_t k, size_t count) {
  const size_t begin = static_cast<size_t>(k) * kTrianglesPerChunk;
  return {begin, std::min(count, begin + kTrianglesPerChunk)};
}

// The vertex range [begin, end) of one part. A part writes only what belongs to its own vertices.
struct VertexPart {
  uint32_t begin, end;
  bool holds(uint32_t v) const { return v - begin < end - begin; }
};

// The parts, and the triangles each reads: those of the chunks whose vertex range meets the
// part's. The meshes the engine makes number their vertices as the march makes them, so a
// chunk's triangles use a narrow range of vertices and a part reads little more than its share of
// the triangles (embryo's eps 0 mesh: 1.06 reads per triangle in 2 parts, 1.5 in 8, where each
// part read every triangle). A mesh in another order gets a few parts that each read everything.
// A part reads its chunks in increasing order, so it meets its vertices' triangles in the mesh's
// order: a sum per vertex adds them as one walk over the triangles does, on any number of threads.
struct VertexParts {
  std::vector<VertexPart> parts;
  bool every_triangle = true;                 // one part: it reads all triangles
  std::vector<uint32_t> first_chunk, chunks;  // else part p's chunks: chunks[first_chunk[p] ..)

  template <class F>
  void for_each_triangle(size_t p, const Mesh::Array<std::array<uint32_t, 3>>& triangles, const F& f) const {
    if (every_triangle) {
      for (const auto& tri : triangles) f(tri);
      return;
    }
    for (uint32_t k = first_chunk[p]; k < first_chunk[p + 1]; ++k) {
      const auto [begin, end] = chunk_triangles(chunks[k], triangles.size());
      for (size_t t = begin; t < end; ++t) f(triangles[t]);
    }
  }
  // The same triangles, last first.
  template <class F>
  void for_each_triangle_backwards(size_t p, const Mesh::Array<std::array<uint32_t, 3>>& triangles, const F& f) const {
    if (every_triangle) {
      for (size_t t = triangles.size(); t-- > 0;) f(triangles[t]);
      return;
    }
    for (uint32_t k = first_chunk[p + 1]; k-- > first_chunk[p];) {
      const auto [begin, end] = chunk_triangles(chunks[k], triangles.size());
      for (size_t t = end; t-- > begin;) f(triangles[t]);
    }
  }
};

// The parts of a mesh of N vertices: as many as balance the threads (one when the work is serial),
// fewer while they would read more than twice the triangles between them.
VertexParts plan_vertex_parts(size_t n, const Mesh::Array<std::array<uint32_t, 3>>& triangles);

}  // namespace isotope
