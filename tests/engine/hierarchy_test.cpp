// The implicit bisection hierarchy: everything computed from coordinates agrees with an
// explicit recursion of the paper's children rule (Sec. 3.1).
#include <gtest/gtest.h>

#include <algorithm>
#include <functional>
#include <map>
#include <set>
#include <vector>

#include "engine/hierarchy/diamond.h"
#include "engine/hierarchy/kuhn.h"
#include "engine/hierarchy/lattice.h"

namespace isotope {
namespace {

using TetKey = std::vector<int64_t>;

struct Recursion {
  std::map<int64_t, std::set<TetKey>> tets_of;  // refinement vertex -> its tetrahedra
  std::map<int64_t, std::pair<int64_t, int64_t>> edge_of;
  std::map<int64_t, std::set<int>> levels_of;
  std::set<TetKey> leaves;
  int longest_edge_mismatches = 0;
};

std::pair<int64_t, int64_t> edge(int64_t a, int64_t b) { return {std::min(a, b), std::max(a, b)}; }

TetKey key(const Lattice& l, const std::array<Coord, 4>& t) {
  TetKey k{l.index(t[0]), l.index(t[1]), l.index(t[2]), l.index(t[3])};
  std::sort(k.begin(), k.end());
  return k;
}

Recursion recurse(const Lattice& l) {
  Recursion r;
  std::function<void(std::array<Coord, 4>, int)> visit = [&](std::array<Coord, 4> t, int level) {
    if (level == l.max_level()) {
      r.leaves.insert(key(l, t));
      return;
    }
    Coord v;
    for (int i = 0; i < 3; ++i) v[i] = (t[0][i] + t[1][i]) / 2;
    if (longest_edge_midpoint(t) != v) ++r.longest_edge_mismatches;
    const int64_t vi = l.index(v);
    r.edge_of[vi] = edge(l.index(t[0]), l.index(t[1]));
    r.levels_of[vi].insert(level);
    r.tets_of[vi].insert(key(l, t));
    if (level % 3 == 0) {
      visit({t[0], t[2], t[3], v}, level + 1);
      visit({t[1], t[3], t[2], v}, level + 1);
    } else {
      visit({t[0], t[2], t[3], v}, level + 1);
      visit({t[1], t[2], t[3], v}, level + 1);
    }
  };
  const int64_t n = l.n;
  for (const Tet& root : kuhn_tetrahedra({0, 0, 0}, {n, n, n})) visit(root, 0);
  return r;
}

Lattice lattice_of(int k) { return Lattice::enclosing({(int64_t{1} << k) + 1, 2, 2}); }

class HierarchyByDepth : public ::testing::TestWithParam<int> {};

TEST_P(HierarchyByDepth, EveryNodeButTheCornersIsTheRefinementVertexOfExactlyOneEdge) {
  const Lattice l = lattice_of(GetParam());
  const Recursion r = recurse(l);
  EXPECT_EQ(static_cast<int64_t>(r.tets_of.size()), l.node_count() - 8);
  for (const auto& [v, levels] : r.levels_of) EXPECT_EQ(levels.size(), 1u) << "node " << v;
  EXPECT_EQ(r.longest_edge_mismatches, 0) << "the refinement edge is the unique longest edge";
}

TEST_P(HierarchyByDepth, DiamondFromCoordinatesMatchesTheRecursion) {
  const Lattice l = lattice_of(GetParam());
  const Recursion r = recurse(l);
  const size_t ring_tets[3] = {6, 4, 8};
  for (const auto& [vi, tets] : r.tets_of) {
    const Diamond d = diamond_of(l.coord(vi), l);
    EXPECT_EQ(d.level, *r.levels_of.at(vi).begin());
    EXPECT_EQ(edge(l.index(d.a), l.index(d.b)), r.edge_of.at(vi));
    EXPECT_EQ(d.level % 3, static_cast<int>(d.type)) << "cube, octahedron, diamond at l mod 3 = 0, 1, 2";
    std::set<TetKey> mine;
    for (int i = 0; i < d.ring_count; ++i) {
      const Coord& p = d.ring[i];
      const Coord& q = d.ring[(i + 1) % d.ring_count];
      if (!l.contains(p) || !l.contains(q)) continue;
      mine.insert(key(l, {d.a, d.b, p, q}));
      // Preprocessing relies on this: a child (end, v, p, q) is bisected at the midpoint of
      // `end` and the farther of p and q.
      for (const Coord& end : {d.a, d.b}) {
        auto dist = [&](const Coord& x) {
          int64_t s = 0;
          for (int c = 0; c < 3; ++c) s += (x[c] - end[c]) * (x[c] - end[c]);
          return s;
        };
        const Coord& far = dist(p) > dist(q) ? p : q;
        ASSERT_NE(dist(p), dist(q));
        const Coord mid{(end[0] + far[0]) / 2, (end[1] + far[1]) / 2, (end[2] + far[2]) / 2};
        EXPECT_EQ(longest_edge_midpoint({end, d.v, p, q}), mid);
      }
    }
    EXPECT_EQ(mine, tets) << "node " << vi;
    // Inside the domain the diamond is whole; on its faces it is cut to 2 or 4 tetrahedra.
    const size_t whole = ring_tets[static_cast<int>(d.type)];
    EXPECT_TRUE(tets.size() == whole || tets.size() * 2 == whole || tets.size() * 4 == whole) << tets.size();
  }
}

TEST_P(HierarchyByDepth, LeavesAreTheKuhnTetrahedraAroundEachCellsEvenDiagonal) {
  const Lattice l = lattice_of(GetParam());
  std::set<TetKey> kuhn;
  for (int64_t z = 0; z < l.n; ++z)
    for (int64_t y = 0; y < l.n; ++y)
      for (int64_t x = 0; x < l.n; ++x)
        for (const Tet& t : cell_tetrahedra({x, y, z})) kuhn.insert(key(l, t));
  EXPECT_EQ(recurse(l).leaves, kuhn);
}

INSTANTIATE_TEST_SUITE_P(Depths, HierarchyByDepth, ::testing::Values(1, 2, 3, 4));

TEST(Lattice, EnclosesAnyDimensionsInTheSmallestPowerOfTwo) {
  EXPECT_EQ(Lattice::enclosing({65, 65, 65}).n, 64);
  EXPECT_EQ(Lattice::enclosing({66, 66, 66}).n, 128);
  EXPECT_EQ(Lattice::enclosing({70, 123, 66}).n, 128);
  EXPECT_EQ(Lattice::enclosing({301, 324, 56}).n, 512);
  EXPECT_EQ(Lattice::enclosing({2, 2, 2}).n, 1);
}

}  // namespace
}  // namespace isotope
