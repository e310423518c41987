#pragma once
// The finest uniform eps whose mesh stays within a triangle budget, in one walk of the tree.
//
// A tetrahedron bisected at diamond v is refined iff key(v) >= eps (engine/extract/traversal.h), and keys
// never grow downwards, so the mesh for eps is the cut "every tetrahedron with key >= eps split".
// Starting from the roots, the walk keeps the current cut (its front) in a max-heap by key and
// splits the front in decreasing key order, one group of equal keys at a time; after a group of
// key x the front is exactly the mesh for eps = x, and its triangle count is kept as a running
// sum. It stops at the first group that would exceed the budget. Cost: one traversal down to the
// answer's cut, memory proportional to that cut, instead of one extraction per trial eps.
#include <cmath>
#include <cstdint>
#include <limits>
#include <queue>
#include <stdexcept>
#include <string>
#include <vector>

#include "engine/extract/traversal.h"

namespace isotope {

struct BudgetChoice {
  double eps = 0;  // in the source's value units (codes, for a quantized store)
  int64_t triangles = 0;
  double next_eps = 0;  // the next finer step, and its triangles (0: eps is full resolution)
  int64_t next_triangles = 0;
  int64_t steps = 0;
};

// The walk for any key that never grows from a diamond to its children: `key(t, level, &k)`
// judges tetrahedron t (engine/extract/traversal.h, Traversal::judge's fates) and, when it may be split,
// sets its key. Returns the smallest threshold x (a key, or just above the largest) such that
// splitting every tetrahedron with key >= x gives at most max_triangles; throws when even the
// keys of +infinity alone exceed it.
template <TraversalSource Source, class Key>
BudgetChoice choose_cut_for_budget(const Source& source, const traversal::SplitRule& rule, int64_t max_triangles,
                                   const Key& judge);

template <TraversalSource Source>
BudgetChoice choose_eps_for_budget(const Source& source, const traversal::SplitRule& rule, int64_t max_triangles) {
  return choose_cut_for_budget(source, rule, max_triangles,
                               [](traversal::Traversal<Source>& walk, const traversal::PackedTet& t, int level,
                                  double* key) { return walk.judge(t, level, key); });
}

// Simplify mode with a budget and no delta (engine/extract/options.h, ExtractOptions::auto_delta): at
// eps = infinity a tetrahedron is split iff its diamond reaches past the data box, or the exact
// rule fires below it with a weight >= delta; the weight (saturated, so never growing downwards)
// is the key. The smallest delta whose mesh at eps = infinity has at most max_triangles: the
// features of smallest weight dropped first, the rest kept.
template <TraversalSource Source>
BudgetChoice choose_delta_for_budget(const Source& source, const traversal::SplitRule& rule, int64_t max_triangles) {
  using Walk = traversal::Traversal<Source>;
  return choose_cut_for_budget(source, rule, max_triangles,
                               [&](Walk& walk, const traversal::PackedTet& t, int level, double* key) {
                                 double error_key = 0;
                                 const auto fate = walk.judge_topology(t, level, &error_key, key);
                                 if (fate == Walk::Fate::split_key && std::isinf(error_key))
                                   *key = std::numeric_limits<double>::infinity();
                                 return fate;
                               });
}

template <TraversalSource Source, class Key>
BudgetChoice choose_cut_for_budget(const Source& source, const traversal::SplitRule& rule, int64_t max_triangles,
                                   const Key& judge) {
  using namespace traversal;
  struct Item {
    double key;
    PackedTet tet;
    int level;
    bool positive;
    int triangles;
    bool operator<(const Item& o) const { return key < o.key; }
  };
  Traversal<Source> walk(source, rule);
  std::priority_queue<Item> front;
  int64_t count = 0;
  auto add = [&](const PackedTet& t, int level, bool positive) {
    double key = 0;
    const auto fate = judge(walk, t, level, &key);
    if (fate == Traversal<Source>::Fate::culled) return;
    const int tris = walk.triangles(t, level);
    count += tris;
    // A key of -infinity is never split (choose_delta_for_budget: no critical point below).
    if (fate == Traversal<Source>::Fate::split_key && key > -std::numeric_limits<double>::infinity())
      front.push({key, t, level, positive, tris});
  };
  auto split_group = [&](double key) {
    while (!front.empty() && front.top().key == key) {
      const Item it = front.top();
      front.pop();
      count -= it.triangles;
      for (const Child& c : bisect(it.tet, it.level, it.positive)) add(c.tet, it.level + 1, c.positive);
    }
  };
  for (const Child& r : walk.roots()) add(r.tet, 0, r.positive);
  constexpr double kInf = std::numeric_limits<double>::infinity();
  split_group(kInf);  // what the topology mode refines whatever eps is
  if (count > max_triangles) {
    const TopologyMode mode = rule.options().topology;
    throw std::runtime_error(
        "a budget of " + std::to_string(max_triangles) +
        " triangles is below the coarsest mesh this topology mode allows (" + std::to_string(count) + " triangles)" +
        (mode == TopologyMode::preserve || mode == TopologyMode::paper
             ? "; topology mode simplify with a budget and no delta drops the smallest features to fit"
             : ""));
  }
  BudgetChoice choice;
  choice.triangles = count;
  choice.eps = front.empty() ? 0 : std::nextafter(front.top().key, kInf);
  while (!front.empty()) {
    const double key = front.top().key;
    split_group(key);
    ++choice.steps;
    if (count > max_triangles) {
      choice.next_eps = key;
      choice.next_triangles = count;
      return choice;
    }
    choice.eps = key;
    choice.triangles = count;
  }
  choice.eps = 0;  // everything refined: the full-resolution mesh
  return choice;
}

}  // namespace isotope
