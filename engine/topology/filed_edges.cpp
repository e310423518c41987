#include "engine/topology/filed_edges.h"

#include <algorithm>
#include <array>
#include <cstdint>
#include <vector>

#include "engine/core/huge_blocks.h"
#include "engine/core/parallel.h"
#include "engine/mesh/vertex_parts.h"

namespace isotope {
namespace {

// The order of a vertex's entries, and which of two vertices is lower, are data a branch cannot
// predict: half its guesses are wrong, some 15 cycles each, and they were much of the filing's cost
// (embryo's eps 0 mesh, 2.5 M triangles, simulated on one thread: 13 M mispredicted branches, 7 M
// with the masks below).

// The lower and the higher of a and b.
inline std::array<uint32_t, 2> ordered(uint32_t a, uint32_t b) {
  const uint32_t lo = a ^ ((a ^ b) & (0u - static_cast<uint32_t>(b < a)));
  return {lo, a ^ b ^ lo};
}

inline void exchange(uint32_t& a, uint32_t& b) {
  const auto [low, high] = ordered(a, b);
  a = low;
  b = high;
}

// Sorts x[0 .. 8): Knuth's network of 19 compare-exchanges.
inline void sort8(uint32_t* x) {
  exchange(x[0], x[2]), exchange(x[1], x[3]), exchange(x[4], x[6]), exchange(x[5], x[7]);
  exchange(x[0], x[4]), exchange(x[1], x[5]), exchange(x[2], x[6]), exchange(x[3], x[7]);
  exchange(x[0], x[1]), exchange(x[2], x[3]), exchange(x[4], x[5]), exchange(x[6], x[7]);
  exchange(x[2], x[4]), exchange(x[3], x[5]);
  exchange(x[1], x[4]), exchange(x[3], x[6]);
  exchange(x[1], x[2]), exchange(x[3], x[4]), exchange(x[5], x[6]);
}

// Union-find over vertex indices. A root is only ever linked below a smaller index, so a set's root
// is its lowest vertex, and every vertex's parent is at most itself. Not for concurrent unions:
// the parts join the edges within their own vertex range at once (their finds stay in that range),
// then the edges between parts are joined on one thread. Concurrent unions of all edges took a
// locked compare-and-swap for every link and every halving step: a tenth of the filing's time.
class Forest {
 public:
  explicit Forest(size_t n) { detail::resize_prefaulted_in_parallel(parent_, n); }
  // Makes each vertex of [begin, end) a set of its own; the parts do it for their vertices.
  void reset(uint32_t begin, uint32_t end) {
    for (uint32_t v = begin; v < end; ++v) parent_[v] = v;
  }
  uint32_t find(uint32_t x) {
    while (parent_[x] != x) {
      const uint32_t g = parent_[parent_[x]];
      parent_[x] = g;  // path halving
      x = g;
    }
    return x;
  }
  // find without path halving: for many threads at once, once the unions are done.
  uint32_t root(uint32_t x) const {
    while (parent_[x] != x) x = parent_[x];
    return x;
  }
  // Joins the sets of a and b and returns the root of the joined set. A caller that keeps the
  // root of one vertex's set passes it as a: from a root, find is one load.
  uint32_t unite(uint32_t a, uint32_t b) {
    const auto [low, high] = ordered(find(a), find(b));
    parent_[high] = low;  // when they are one root, its own parent already
    return low;
  }

 private:
  std::vector<uint32_t> parent_;
};

struct EdgeCounts {
  int64_t edges = 0, boundary = 0, nonmanifold = 0;
};

// Sorts [begin, end) in place, counts its distinct values as edges (held by one triangle:
// boundary, by three or more: non-manifold) and calls unite(w) for each. A surface's vertex has 0
// to 24 entries (its upper neighbours, each edge twice), six on average, three quarters at most
// eight: those are sorted by the network, padded with UINT32_MAX, which no vertex index reaches.
template <class Unite>
void count_entries(uint32_t* begin, uint32_t* end, EdgeCounts& c, const Unite& unite) {
  const ptrdiff_t k = end - begin;
  if (k <= 8) {
    uint32_t x[8];
    for (ptrdiff_t i = 0; i < 8; ++i) x[i] = i < k ? begin[i] : UINT32_MAX;
    sort8(x);
    for (ptrdiff_t i = 0; i < k; ++i) begin[i] = x[i];
  } else {
    std::sort(begin, end);
  }
  for_each_run(begin, end, [&](uint32_t w, ptrdiff_t triangles) {
    ++c.edges;
    c.boundary += triangles == 1;
    c.nonmanifold += triangles > 2;
    unite(w);
  });
}

}  // namespace

template <class Offset>
FiledEdges<Offset> file_edges(const Mesh& mesh) {
  const size_t n = mesh.positions.size();
  const Mesh::Array<std::array<uint32_t, 3>>& triangles = mesh.triangles;
  FiledEdges<Offset> e;
  const VertexParts plan = plan_vertex_parts(n, triangles);
  const size_t parts = plan.parts.size();
  // Each undirected edge is filed under its lower vertex: a part counts its vertices' edges (into
  // first[v], which is then turned into v's end), fills them in backwards, and then sorts and counts
  // each vertex's few entries while they are in cache (one sort of all 3F edges took most of the
  // time: 20 ms of a 100k-triangle mesh that `isotope serve` answers interactively). A part counts
  // and files only the edge ends and corners whose vertex is its own, so no add is locked (locked
  // adds over tasks of triangles took a full memory barrier for every edge end: 132 -> 98 ms on two
  // threads for embryo's 2.5 M-triangle eps 0 mesh when they went).
  detail::resize_prefaulted_in_parallel(e.first, n + 1);  // zero: the counts start there
  detail::resize_prefaulted_in_parallel(e.used, n);
  Forest forest(n);
  std::vector<Offset> total(parts + 1, 0);
  parallel_for(int64_t{0}, static_cast<int64_t>(parts), [&](int64_t p) {
    const VertexPart part = plan.parts[static_cast<size_t>(p)];
    forest.reset(part.begin, part.end);
    plan.for_each_triangle(static_cast<size_t>(p), triangles, [&](const std::array<uint32_t, 3>& tri) {
      for (int k = 0; k < 3; ++k) {
        const uint32_t a = tri[static_cast<size_t>(k)], lo = ordered(a, tri[static_cast<size_t>((k + 1) % 3)])[0];
        if (part.holds(lo)) ++e.first[lo];
        if (part.holds(a)) e.used[a] = 1;
      }
    });
    Offset sum = 0;
    for (uint32_t v = part.begin; v < part.end; ++v) sum += e.first[v];
    total[static_cast<size_t>(p) + 1] = sum;
  });
  for (size_t p = 0; p < parts; ++p) total[p + 1] += total[p];
  e.first[n] = total[parts];
  detail::resize_prefaulted_in_parallel(e.upper, static_cast<size_t>(total[parts]));
  std::vector<EdgeCounts> counts(parts);
  std::vector<std::vector<std::array<uint32_t, 2>>> between(parts);  // per part: its edges to later parts
  parallel_for(int64_t{0}, static_cast<int64_t>(parts), [&](int64_t p) {
    const VertexPart part = plan.parts[static_cast<size_t>(p)];
    Offset end = total[static_cast<size_t>(p)];
    for (uint32_t v = part.begin; v < part.end; ++v) e.first[v] = end += e.first[v];  // v's end, for now
    // Filled backwards from each vertex's end, so that first[v] ends at v's start; the triangles
    // last first, so that a vertex's entries still come in the triangles' order (the order the
    // sorts below were measured with).
    plan.for_each_triangle_backwards(static_cast<size_t>(p), triangles, [&](const std::array<uint32_t, 3>& tri) {
      for (int k = 3; k-- > 0;) {
        const auto [lo, hi] = ordered(tri[static_cast<size_t>(k)], tri[static_cast<size_t>((k + 1) % 3)]);
        if (part.holds(lo)) e.upper[--e.first[lo]] = hi;  // first[lo] ends at lo's start
      }
    });
    // Per vertex, while its entries are in cache: its distinct upper ends; each edge joins two
    // vertices' components, here when both are the part's, after all parts when not.
    EdgeCounts& c = counts[static_cast<size_t>(p)];
    std::vector<std::array<uint32_t, 2>>& later = between[static_cast<size_t>(p)];
    for (uint32_t v = part.begin; v < part.end; ++v) {
      uint32_t* const from = e.upper.data() + e.first[v];
      uint32_t* const to = e.upper.data() + (v + 1 == part.end ? total[static_cast<size_t>(p) + 1] : e.first[v + 1]);
      uint32_t root = forest.find(v);
      count_entries(from, to, c, [&](uint32_t w) {
        if (w < part.end)
          root = forest.unite(root, w);
        else
          later.push_back({v, w});
      });
    }
  });
  for (const auto& edges : between)
    for (const auto& [v, w] : edges) forest.unite(v, w);
  for (const EdgeCounts& c : counts) {
    e.edges += c.edges;
    e.boundary_edges += c.boundary;
    e.nonmanifold_edges += c.nonmanifold;
  }
  detail::resize_prefaulted_in_parallel(e.root, n);
  parallel_for(int64_t{0}, static_cast<int64_t>(parts), [&](int64_t p) {
    const VertexPart part = plan.parts[static_cast<size_t>(p)];
    for (uint32_t v = part.begin; v < part.end; ++v) e.root[v] = forest.root(v);
  });
  return e;
}

template FiledEdges<uint32_t> file_edges<uint32_t>(const Mesh& mesh);
template FiledEdges<uint64_t> file_edges<uint64_t>(const Mesh& mesh);

}  // namespace isotope
