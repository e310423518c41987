#include "engine/topology/filed_edges.h"

#include <algorithm>
#include <atomic>
#include <vector>

#include "engine/core/parallel.h"

namespace isotope {
namespace {

// Triangles per parallel task: enough to pay for a task, few enough to balance two threads on a
// mesh of a few hundred thousand triangles (what `isotope serve` measures per request).
constexpr int64_t kTrianglesPerTask = int64_t{1} << 15;

int64_t tasks_for(size_t items) { return static_cast<int64_t>((items + kTrianglesPerTask - 1) / kTrianglesPerTask); }

// Union-find over vertex indices whose unions may run concurrently: a root is only ever linked
// below a smaller index, by compare-and-swap, so concurrent unions of the same sets agree.
class ConcurrentForest {
 public:
  explicit ConcurrentForest(size_t n) : parent_(n) {
    parallel_for(int64_t{0}, tasks_for(n), [&](int64_t t) {
      const size_t end = std::min(n, static_cast<size_t>(t + 1) * kTrianglesPerTask);
      for (size_t v = static_cast<size_t>(t) * kTrianglesPerTask; v < end; ++v)
        parent_[v].store(static_cast<uint32_t>(v), std::memory_order_relaxed);
    });
  }
  uint32_t find(uint32_t x) {
    for (;;) {
      uint32_t p = parent_[x].load(std::memory_order_relaxed);
      if (p == x) return x;
      const uint32_t g = parent_[p].load(std::memory_order_relaxed);
      if (g != p) parent_[x].compare_exchange_weak(p, g, std::memory_order_relaxed);  // path halving
      x = g;
    }
  }
  void unite(uint32_t a, uint32_t b) {
    for (;;) {
      a = find(a);
      b = find(b);
      if (a == b) return;
      if (a < b) std::swap(a, b);  // link the larger root below the smaller
      uint32_t expected = a;
      if (parent_[a].compare_exchange_strong(expected, b, std::memory_order_relaxed)) return;
    }
  }

 private:
  std::vector<std::atomic<uint32_t>> parent_;
};

// The vertex range [begin, end) of one part of the filing passes below. Each part reads every
// triangle and counts or files only the edge ends and corners whose vertex is its own, so no two
// threads write one counter and no add is locked (the passes made two locked adds for every edge
// end, each one a full memory barrier even when no other thread touches the counter). Against locked
// adds over tasks of triangles, best of 7 on two threads: 57 -> 43 ms for a 956 k-triangle coarse
// mesh (1024^3 algebraic store, 1 M budget), 132 -> 98 ms for embryo's 2.5 M-triangle eps-0 mesh.
// Each part reads all triangles (12 bytes a triangle, in order), so a part per thread on many
// cores would read them many times over, and where the parts run one after another (nested in a
// busy parallel loop, as the server measures beside the normals) one thread reads them that many
// times: kMostParts bounds both. Measured on two threads only.
constexpr int64_t kMostParts = 4;
struct VertexPart {
  uint32_t begin, end;
  bool holds(uint32_t v) const { return v - begin < end - begin; }
};

template <class Body>
void for_each_part(size_t n, size_t triangles, const Body& body) {
  const int64_t parts = runs_serially(0, tasks_for(triangles)) ? 1 : std::min(thread_count(), kMostParts);
  parallel_for(int64_t{0}, parts, [&](int64_t p) {
    const auto at = [&](int64_t q) {
      return static_cast<uint32_t>(n * static_cast<size_t>(q) / static_cast<size_t>(parts));
    };
    body(VertexPart{at(p), at(p + 1)});
  });
}

}  // namespace

template <class Offset>
FiledEdges<Offset> file_edges(const Mesh& mesh) {
  const size_t n = mesh.positions.size();
  FiledEdges<Offset> e;
  // Each undirected edge is filed under its lower vertex (counting pass, then filling): a vertex's
  // few entries are then sorted in place, where one sort of all 3F edges took most of the time
  // (20 ms of a 100k-triangle mesh that `isotope serve` answers interactively).
  std::vector<Offset> count(n + 1, 0);
  e.used.assign(n, 0);
  for_each_part(n, mesh.triangles.size(), [&](VertexPart part) {
    for (const auto& tri : mesh.triangles)
      for (int k = 0; k < 3; ++k) {
        const uint32_t a = tri[static_cast<size_t>(k)], lo = std::min(a, tri[static_cast<size_t>((k + 1) % 3)]);
        if (part.holds(lo)) ++count[lo + 1];
        if (part.holds(a)) e.used[a] = 1;
      }
  });
  e.first.assign(n + 1, 0);
  for (size_t v = 1; v <= n; ++v) e.first[v] = e.first[v - 1] + count[v];
  std::copy(e.first.begin(), e.first.end() - 1, count.begin());  // count[v] becomes v's fill position
  e.upper.resize(e.first.back());
  for_each_part(n, mesh.triangles.size(), [&](VertexPart part) {
    for (const auto& tri : mesh.triangles)
      for (int k = 0; k < 3; ++k) {
        const uint32_t a = tri[static_cast<size_t>(k)], b = tri[static_cast<size_t>((k + 1) % 3)];
        if (part.holds(std::min(a, b))) e.upper[count[std::min(a, b)]++] = std::max(a, b);
      }
  });
  // Per vertex: its upper ends sorted; each edge joins two vertices' components.
  ConcurrentForest forest(n);
  struct Counts {
    int64_t edges = 0, boundary = 0, nonmanifold = 0;
  };
  std::vector<Counts> per_task(static_cast<size_t>(tasks_for(n)));
  parallel_for(int64_t{0}, tasks_for(n), [&](int64_t task) {
    Counts& c = per_task[static_cast<size_t>(task)];
    const size_t end = std::min(n, static_cast<size_t>(task + 1) * kTrianglesPerTask);
    for (size_t v = static_cast<size_t>(task) * kTrianglesPerTask; v < end; ++v) {
      std::sort(e.upper.begin() + e.first[v], e.upper.begin() + e.first[v + 1]);
      for_each_edge_of(e, v, [&](uint32_t w, int64_t triangles) {
        ++c.edges;
        if (triangles == 1) ++c.boundary;
        if (triangles > 2) ++c.nonmanifold;
        forest.unite(static_cast<uint32_t>(v), w);
      });
    }
  });
  for (const Counts& c : per_task) {
    e.edges += c.edges;
    e.boundary_edges += c.boundary;
    e.nonmanifold_edges += c.nonmanifold;
  }
  e.root.resize(n);
  parallel_for(int64_t{0}, tasks_for(n), [&](int64_t task) {
    const size_t end = std::min(n, static_cast<size_t>(task + 1) * kTrianglesPerTask);
    for (size_t v = static_cast<size_t>(task) * kTrianglesPerTask; v < end; ++v)
      e.root[v] = forest.find(static_cast<uint32_t>(v));
  });
  return e;
}

template FiledEdges<uint32_t> file_edges<uint32_t>(const Mesh& mesh);
template FiledEdges<uint64_t> file_edges<uint64_t>(const Mesh& mesh);

}  // namespace isotope
