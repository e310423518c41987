#include "engine/topology/filed_edges.h"

#include <algorithm>
#include <array>
#include <cstdint>
#include <vector>

#include "engine/core/parallel.h"

namespace isotope {
namespace {

// Triangles per parallel task: enough to pay for a task, few enough to balance two threads on a
// mesh of a few hundred thousand triangles (what `isotope serve` measures per request).
constexpr int64_t kTrianglesPerTask = int64_t{1} << 15;

int64_t tasks_for(size_t items) { return static_cast<int64_t>((items + kTrianglesPerTask - 1) / kTrianglesPerTask); }

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
  explicit Forest(size_t n) : parent_(n) {}
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

// The vertex range [begin, end) of one part of the filing passes below. A part counts and files
// only the edge ends and corners whose vertex is its own, so no two threads write one counter and
// no add is locked (locked adds over tasks of triangles took a full memory barrier for every edge
// end: 132 -> 98 ms on two threads for embryo's 2.5 M-triangle eps 0 mesh when they went).
struct VertexPart {
  uint32_t begin, end;
  bool holds(uint32_t v) const { return v - begin < end - begin; }
};

// The parts, and the triangles each reads: those of the chunks of kTrianglesPerTask triangles
// whose vertex range meets the part's. The meshes the engine makes number their vertices as the
// march makes them, so a chunk's triangles use a narrow range of vertices and a part reads little
// more than its share of the triangles (embryo's eps 0 mesh: 1.06 reads per triangle in 2 parts,
// 1.5 in 8, where each part read every triangle). A mesh in another order gets a few parts that
// each read everything.
constexpr int64_t kMostParts = 64;
constexpr int64_t kMostFullReadParts = 4;  // parts that each read all triangles, at most
struct PartPlan {
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
      const size_t begin = static_cast<size_t>(chunks[k]) * kTrianglesPerTask;
      const size_t end = std::min(triangles.size(), begin + kTrianglesPerTask);
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
      const size_t begin = static_cast<size_t>(chunks[k]) * kTrianglesPerTask;
      const size_t end = std::min(triangles.size(), begin + kTrianglesPerTask);
      for (size_t t = end; t-- > begin;) f(triangles[t]);
    }
  }
};

PartPlan plan_parts(size_t n, const Mesh::Array<std::array<uint32_t, 3>>& triangles) {
  PartPlan plan;
  const int64_t chunk_count = tasks_for(triangles.size());
  const auto equal_parts = [&](int64_t count) {
    plan.parts.resize(static_cast<size_t>(count));
    for (int64_t q = 0; q < count; ++q)
      plan.parts[static_cast<size_t>(q)] = {
          static_cast<uint32_t>(n * static_cast<size_t>(q) / static_cast<size_t>(count)),
          static_cast<uint32_t>(n * static_cast<size_t>(q + 1) / static_cast<size_t>(count))};
  };
  if (runs_serially(0, chunk_count) || n < 2) {
    equal_parts(1);
    return plan;
  }
  std::vector<std::array<uint32_t, 2>> range(static_cast<size_t>(chunk_count));  // lowest, highest vertex
  parallel_for(int64_t{0}, chunk_count, [&](int64_t k) {
    const size_t begin = static_cast<size_t>(k) * kTrianglesPerTask;
    const size_t end = std::min(triangles.size(), begin + kTrianglesPerTask);
    uint32_t lo = UINT32_MAX, hi = 0;
    for (size_t t = begin; t < end; ++t)
      for (const uint32_t v : triangles[t]) {
        lo = std::min(lo, v);
        hi = std::max(hi, v);
      }
    range[static_cast<size_t>(k)] = {lo, hi};
  });
  // The part of vertex v among `count` equal parts (part q begins at n q / count).
  const auto part_of = [&](uint32_t v, int64_t count) {
    const size_t c = static_cast<size_t>(count);
    size_t q = static_cast<size_t>(v) * c / n;
    while (q + 1 < c && n * (q + 1) / c <= v) ++q;
    while (q > 0 && n * q / c > v) --q;
    return static_cast<int64_t>(q);
  };
  const auto reads = [&](int64_t count) {
    int64_t sum = 0;
    for (const auto& r : range) sum += part_of(r[1], count) - part_of(r[0], count) + 1;
    return sum;
  };
  // As many parts as balance the threads, halved while they would read more than twice the
  // triangles between them; down to the few parts that may each read all of them.
  const int64_t full_read_parts = std::min(thread_count(), kMostFullReadParts);
  int64_t count = std::min<int64_t>({4 * thread_count(), kMostParts, static_cast<int64_t>(n)});
  while (count > full_read_parts && reads(count) > 2 * chunk_count) count = std::max(count / 2, full_read_parts);
  equal_parts(count);
  plan.every_triangle = false;
  plan.first_chunk.assign(static_cast<size_t>(count) + 1, 0);
  for (const auto& r : range)
    for (int64_t q = part_of(r[0], count); q <= part_of(r[1], count); ++q)
      ++plan.first_chunk[static_cast<size_t>(q) + 1];
  for (size_t q = 0; q < static_cast<size_t>(count); ++q) plan.first_chunk[q + 1] += plan.first_chunk[q];
  plan.chunks.resize(plan.first_chunk.back());
  std::vector<uint32_t> at(plan.first_chunk.begin(), plan.first_chunk.end() - 1);
  for (size_t k = 0; k < range.size(); ++k)
    for (int64_t q = part_of(range[k][0], count); q <= part_of(range[k][1], count); ++q)
      plan.chunks[at[static_cast<size_t>(q)]++] = static_cast<uint32_t>(k);
  return plan;
}

}  // namespace

template <class Offset>
FiledEdges<Offset> file_edges(const Mesh& mesh) {
  const size_t n = mesh.positions.size();
  const Mesh::Array<std::array<uint32_t, 3>>& triangles = mesh.triangles;
  FiledEdges<Offset> e;
  const PartPlan plan = plan_parts(n, triangles);
  const size_t parts = plan.parts.size();
  // Each undirected edge is filed under its lower vertex: a part counts its vertices' edges (into
  // first[v], which is then turned into v's end), fills them in backwards, and then sorts and counts
  // each vertex's few entries while they are in cache (one sort of all 3F edges took most of the
  // time: 20 ms of a 100k-triangle mesh that `isotope serve` answers interactively).
  e.first.resize(n + 1);  // zero: the counts start there
  e.used.resize(n);
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
  e.upper.resize(static_cast<size_t>(total[parts]));
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
  e.root.resize(n);
  parallel_for(int64_t{0}, static_cast<int64_t>(parts), [&](int64_t p) {
    const VertexPart part = plan.parts[static_cast<size_t>(p)];
    for (uint32_t v = part.begin; v < part.end; ++v) e.root[v] = forest.root(v);
  });
  return e;
}

template FiledEdges<uint32_t> file_edges<uint32_t>(const Mesh& mesh);
template FiledEdges<uint64_t> file_edges<uint64_t>(const Mesh& mesh);

}  // namespace isotope
