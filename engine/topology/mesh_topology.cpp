#include <algorithm>
#include <atomic>
#include <numeric>
#include <vector>

#include "engine/core/parallel.h"
#include "isotope/mesh.h"

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

// Adds one to `c`, returning what it held. A locked add costs about 20 cycles even when no other
// thread touches the counter, and filing the edges makes two for every edge end: on one thread
// (kConcurrent false) a plain load and store, which nothing else can interleave with.
template <bool kConcurrent>
uint32_t bump(std::atomic<uint32_t>& c) {
  if constexpr (kConcurrent) return c.fetch_add(1, std::memory_order_relaxed);
  const uint32_t v = c.load(std::memory_order_relaxed);
  c.store(v + 1, std::memory_order_relaxed);
  return v;
}

template <bool kConcurrent>
MeshTopology measure(const Mesh& mesh) {
  MeshTopology t;
  t.triangles = static_cast<int64_t>(mesh.triangles.size());
  const size_t n = mesh.positions.size();
  const int64_t tasks = tasks_for(mesh.triangles.size());
  // Each undirected edge is filed under its lower vertex (counting pass, then filling): a vertex's
  // few entries are then sorted in place, where one sort of all 3F edges took most of the time
  // (20 ms of a 100k-triangle mesh that `isotope serve` answers interactively). Both passes run on
  // all threads; a 2.5 M-triangle mesh took 126 ms on one. Algebraic 257^3's eps 0 mesh (939 k
  // triangles, the bench's BM_MeshTopology): 23 ms on one thread, 29 ms with locked adds there.
  std::vector<std::atomic<uint32_t>> count(n + 1);
  std::vector<std::atomic<uint8_t>> used(n);
  parallel_for(int64_t{0}, tasks, [&](int64_t task) {
    const size_t end = std::min(mesh.triangles.size(), static_cast<size_t>(task + 1) * kTrianglesPerTask);
    for (size_t i = static_cast<size_t>(task) * kTrianglesPerTask; i < end; ++i) {
      const auto& tri = mesh.triangles[i];
      for (int k = 0; k < 3; ++k) {
        bump<kConcurrent>(count[std::min(tri[k], tri[(k + 1) % 3]) + 1]);
        used[tri[k]].store(1, std::memory_order_relaxed);
      }
    }
  });
  std::vector<uint32_t> first(n + 1, 0);
  for (size_t v = 1; v <= n; ++v) first[v] = first[v - 1] + count[v].load(std::memory_order_relaxed);
  parallel_for(int64_t{0}, tasks_for(n), [&](int64_t task) {  // count[v] becomes v's fill position
    const size_t end = std::min(n, static_cast<size_t>(task + 1) * kTrianglesPerTask);
    for (size_t v = static_cast<size_t>(task) * kTrianglesPerTask; v < end; ++v)
      count[v].store(first[v], std::memory_order_relaxed);
  });
  std::vector<uint32_t> upper(first.back());
  parallel_for(int64_t{0}, tasks, [&](int64_t task) {
    const size_t end = std::min(mesh.triangles.size(), static_cast<size_t>(task + 1) * kTrianglesPerTask);
    for (size_t i = static_cast<size_t>(task) * kTrianglesPerTask; i < end; ++i) {
      const auto& tri = mesh.triangles[i];
      for (int k = 0; k < 3; ++k) {
        const uint32_t a = tri[k], b = tri[(k + 1) % 3];
        upper[bump<kConcurrent>(count[std::min(a, b)])] = std::max(a, b);
      }
    }
  });
  // Per vertex: its distinct upper neighbours are its edges; each joins two vertices' components.
  ConcurrentForest forest(n);
  struct Counts {
    int64_t edges = 0, boundary = 0, nonmanifold = 0, vertices = 0, components = 0;
  };
  std::vector<Counts> per_task(static_cast<size_t>(tasks_for(n)));
  parallel_for(int64_t{0}, tasks_for(n), [&](int64_t task) {
    Counts& c = per_task[static_cast<size_t>(task)];
    const size_t end = std::min(n, static_cast<size_t>(task + 1) * kTrianglesPerTask);
    for (size_t v = static_cast<size_t>(task) * kTrianglesPerTask; v < end; ++v) {
      const auto begin = upper.begin() + first[v], stop = upper.begin() + first[v + 1];
      std::sort(begin, stop);
      for (auto i = begin; i != stop;) {
        const auto j = std::find_if(i, stop, [&](uint32_t w) { return w != *i; });
        ++c.edges;
        if (j - i == 1) ++c.boundary;
        if (j - i > 2) ++c.nonmanifold;
        forest.unite(static_cast<uint32_t>(v), *i);
        i = j;
      }
    }
  });
  parallel_for(int64_t{0}, tasks_for(n), [&](int64_t task) {
    Counts& c = per_task[static_cast<size_t>(task)];
    const size_t end = std::min(n, static_cast<size_t>(task + 1) * kTrianglesPerTask);
    for (size_t v = static_cast<size_t>(task) * kTrianglesPerTask; v < end; ++v) {
      if (!used[v].load(std::memory_order_relaxed)) continue;
      ++c.vertices;
      if (forest.find(static_cast<uint32_t>(v)) == v) ++c.components;
    }
  });
  for (const Counts& c : per_task) {
    t.edges += c.edges;
    t.boundary_edges += c.boundary;
    t.nonmanifold_edges += c.nonmanifold;
    t.vertices += c.vertices;
    t.components += c.components;
  }
  t.euler_characteristic = t.vertices - t.edges + t.triangles;
  return t;
}

}  // namespace

MeshTopology measure_topology(const Mesh& mesh) {
  // The adds run in the passes over the triangles' tasks.
  return runs_serially(0, tasks_for(mesh.triangles.size())) ? measure<false>(mesh) : measure<true>(mesh);
}

}  // namespace isotope
