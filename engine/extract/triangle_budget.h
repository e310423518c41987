#pragma once
// The finest uniform eps whose mesh stays within a triangle budget, counted in parallel passes
// without building any mesh.
//
// A tetrahedron bisected at diamond v is refined iff key(v) >= eps (the traversal's SplitRule), and keys
// never grow downwards, so the mesh for eps is the cut "every tetrahedron with key >= eps split".
// A tetrahedron t whose parent has key kp and whose own key is kt (-infinity at a leaf) lies on
// that cut exactly for eps in (kt, kp]. Hence the triangle count of every cut at once:
//
//   T(x) = sum over keys k >= x of D[k],   D[k] = sum of tris(children) - tris(t) over the t of key k,
//
// with the roots counted at kp = +infinity (docs/METHOD.md, "Focus and triangle budget"). A pass with a
// lower bound L descends every tetrahedron with key >= L, so it knows D, and T, exactly for every
// key >= L, without building any mesh. The tetrahedra it reaches but does not split (key < L) are
// its frontier, kept compactly (a root and one bit per level) for the next pass, which resumes
// there with a lower L: over all passes each tetrahedron is judged once, as in one traversal to
// the cut just below the budget. The first pass runs the subtrees a few levels down in parallel,
// later ones the frontier; each thread sums into its own table, and the sums are exact integers,
// so the choice does not depend on the thread count. L starts at +infinity and falls by at most
// 4x a pass, guided by the growth of T so far. Memory: the frontier (16 bytes a tetrahedron) and
// the distinct keys.
#include <algorithm>
#include <array>
#include <atomic>
#include <bit>
#include <cassert>
#include <cmath>
#include <cstdint>
#include <limits>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "engine/core/mix_hash.h"
#include "engine/core/parallel.h"
#include "engine/extract/traversal.h"
#include "isotope/extract.h"

namespace isotope {

struct BudgetChoice {
  double eps = 0;  // in the source's value units (codes, for a quantized store)
  int ties = -1;   // ExtractOptions::eps_ties: -1, every diamond of key eps refined
  int64_t triangles = 0;
  double next_eps = 0;  // the next finer step, and its triangles (0: eps is full resolution)
  int next_ties = -1;
  int64_t next_triangles = 0;
  int64_t steps = 0;
  // From a sample (BudgetSample): the triangle counts are estimates, and `fits` is false when
  // the keys of +infinity alone seemed to take more than the sample aims at (kSampleAim of the
  // budget): no eps was chosen.
  bool sampled = false;
  bool fits = true;
};

// Which subtrees a search counts. Exact by default. With a level and a stride of 2^bits, of every
// 2^bits tetrahedra of that level below one of the level `bits` above, one only, chosen by a hash of
// their common ancestor, is descended, and what it adds below that level counts 2^bits times: an
// estimate of T stratified over the whole volume, for about 1 / 2^bits of the work
// (docs/METHOD.md, "Focus and triangle budget"). The choice depends on the tree alone, never on the
// threads or the cache.
struct BudgetSample {
  int level = -1;  // < 0: every subtree (exact)
  int bits = 0;
  bool exact() const { return level < 0 || bits == 0; }
  bool keeps(uint8_t root, uint64_t path) const {
    const int group = level - bits;  // the common ancestor's level: its path is the low bits
    const uint64_t h = mix64((path & ((uint64_t{1} << group) - 1)) ^ (uint64_t{root} << 58));
    const uint64_t mask = (uint64_t{1} << bits) - 1;
    return ((path >> group) & mask) == (h & mask);
  }
};

// The search for any key that never grows from a diamond to its children: `key(t, level, &k)`
// judges tetrahedron t (with the fates of Traversal::judge) and, when it may be split,
// sets its key. Returns the smallest threshold x (a key, or just above the largest) such that
// splitting every tetrahedron with key >= x gives at most max_triangles; throws when even the
// keys of +infinity alone exceed it (TriangleBudgetTooSmall). With `ties`, the steps go on within
// one key by tie class (SplitRule::refines): the cut "key > x, or key = x and class < ties".
// With a sample (not exact()), the counts are estimates and the threshold aims at
// kSampleAim of max_triangles; a budget the estimate cannot meet returns fits = false instead of
// throwing.
template <TraversalSource Source, class Key>
BudgetChoice choose_cut_for_budget(const Source& source, const traversal::SplitRule& rule, int64_t max_triangles,
                                   bool ties, const Key& judge, BudgetSample sample = {});

// Where a sampled choice aims, and the least part of the budget its mesh must reach to be kept
// (docs/METHOD.md, "Focus and triangle budget"): an estimate off by up to 5% either way still lands in
// [kSampleFloor, 1] of the budget.
inline constexpr double kSampleAim = 0.95, kSampleFloor = 0.9;

template <TraversalSource Source>
BudgetChoice choose_eps_for_budget(const Source& source, const traversal::SplitRule& rule, int64_t max_triangles,
                                   BudgetSample sample = {}) {
  return choose_cut_for_budget(
      source, rule, max_triangles, true,
      [](traversal::Traversal<Source>& walk, const traversal::PackedTet& t, int level, double* key) {
        return walk.judge(t, level, key);
      },
      sample);
}

// Simplify mode with a budget and no delta (ExtractOptions::auto_delta): at
// eps = infinity a tetrahedron is split iff the exact rule fires below it with a weight >= delta
// (or its error key is infinite: at a focus's centre); the weight (saturated, so never growing
// downwards) is the key. The smallest delta whose mesh at eps = infinity has at most max_triangles: the
// features of smallest weight dropped first, the rest kept.
template <TraversalSource Source>
BudgetChoice choose_delta_for_budget(const Source& source, const traversal::SplitRule& rule, int64_t max_triangles) {
  using Walk = traversal::Traversal<Source>;
  return choose_cut_for_budget(source, rule, max_triangles, false,
                               [&](Walk& walk, const traversal::PackedTet& t, int level, double* key) {
                                 double error_key = 0;
                                 const auto fate = walk.judge_topology(t, level, &error_key, key);
                                 if (fate == Walk::Fate::split_key && std::isinf(error_key))
                                   *key = std::numeric_limits<double>::infinity();
                                 return fate;
                               });
}

namespace budget_detail {

// A key and a tie class (SplitRule::tie_class; 0 where ties are not counted).
struct TieKey {
  double key;
  int tie;
  bool operator==(const TieKey&) const = default;
};

// Sums by TieKey in one array, probed linearly: the passes add to it for every run of
// tetrahedra that changes key or class, and a node-based map's lookups were a few percent of a
// search. Keys compare as doubles (0 and -0 are one key, as they are one eps).
class TieKeySums {
 public:
  int64_t& operator[](const TieKey& k) {
    if (2 * (size_ + 1) > slots_.size()) grow();
    Slot& s = find(slots_, k);
    if (!s.used) s = {k, 0, true}, ++size_;
    return s.sum;
  }
  size_t size() const { return size_; }
  void clear() { slots_.clear(), size_ = 0; }
  // f(key, sum) for every key, in no particular order.
  template <class F>
  void for_each(F&& f) const {
    for (const Slot& s : slots_)
      if (s.used) f(s.key, s.sum);
  }

 private:
  struct Slot {
    TieKey key{0, 0};
    int64_t sum = 0;
    bool used = false;
  };
  static Slot& find(std::vector<Slot>& slots, const TieKey& k) {
    const size_t mask = slots.size() - 1;
    const double key = k.key + 0.0;  // -0 hashes as 0
    size_t i = mix64(std::bit_cast<uint64_t>(key) ^ (static_cast<uint64_t>(static_cast<uint32_t>(k.tie)) << 1)) & mask;
    while (slots[i].used && !(slots[i].key == k)) i = (i + 1) & mask;
    return slots[i];
  }
  void grow() {
    std::vector<Slot> bigger(std::max<size_t>(64, 2 * slots_.size()));
    for (const Slot& s : slots_)
      if (s.used) find(bigger, s.key) = s;
    slots_ = std::move(bigger);
  }
  std::vector<Slot> slots_;  // a power of two, at most half used
  size_t size_ = 0;
};

// D of the passes so far (see the top of this file) by key and tie class, exact for the keys >=
// the last bound.
struct KeyTable {
  TieKeySums d;

  // Consecutive tetrahedra often share a key and class (saturated errors, siblings): one pending
  // sum saves many lookups.
  void add(double key, int tie, int64_t delta) {
    if (key != pending_.key || tie != pending_.tie || !has_pending_) {
      flush();
      pending_ = {key, tie}, has_pending_ = true;
    }
    pending_sum_ += delta;
  }
  void flush() {
    if (has_pending_) d[pending_] += pending_sum_;
    has_pending_ = false, pending_sum_ = 0;
  }
  void merge(KeyTable& other) {
    other.flush();
    other.d.for_each([&](const TieKey& k, int64_t v) { d[k] += v; });
    other.d.clear();
  }

 private:
  TieKey pending_{0, 0};
  int64_t pending_sum_ = 0;
  bool has_pending_ = false;
};

// A tetrahedron the last pass reached but did not split (its key is below the bound), kept for
// the next pass by the way down to it: which root, then one bit per level for the child taken,
// packed with a marker bit above the path that tells its length (at most 57 levels: 3 per doubling
// of a lattice of at most 2^19 cells a side). 16 bytes: the frontier is most of the fresh memory a
// search touches.
struct FrontierItem {
  static constexpr int kRootShift = 58;
  double key;
  uint64_t where;

  static FrontierItem at(double key, uint8_t root, int level, uint64_t path) {
    assert(level < kRootShift && root < (1 << (64 - kRootShift)));
    return {key, (uint64_t{root} << kRootShift) | (uint64_t{1} << level) | path};
  }
  uint8_t root() const { return static_cast<uint8_t>(where >> kRootShift); }
  int level() const { return static_cast<int>(std::bit_width(where & ((uint64_t{1} << kRootShift) - 1))) - 1; }
  uint64_t path() const { return where & ((uint64_t{1} << level()) - 1); }
};
static_assert(sizeof(FrontierItem) == 16);

// The passes of one search: the first descends from the roots (the subtrees at a few levels down
// in parallel), each later one descends, in parallel, the frontier items whose key reaches its
// bound and keeps the rest. Every tetrahedron is judged once over all passes.
template <TraversalSource Source, class Key>
class CountPasses {
 public:
  using Walk = traversal::Traversal<Source>;
  CountPasses(const Source& source, const traversal::SplitRule& rule, bool ties, const Key& judge, BudgetSample sample)
      : source_(source), rule_(rule), ties_(ties), judge_(judge), sample_(sample) {
    workers_.resize(static_cast<size_t>(std::max<int64_t>(thread_count(), 1)));
  }

  const TieKeySums& d() const { return table_.d; }
  // The largest key of the frontier: -infinity once every split is counted.
  double largest_below() const { return largest_below_; }

  void first(double bound, int seed_level) {
    bound_ = bound;
    std::vector<Seed> seeds;
    Worker top;
    {
      Walk walk(source_, rule_);
      roots_ = walk.roots();
      assert(roots_.size() <= (size_t{1} << (64 - FrontierItem::kRootShift)));  // 6 Kuhn tetrahedra
      for (size_t r = 0; r < roots_.size(); ++r) {
        const traversal::Child& c = roots_[r];
        top.table.add(kInf, 0,
                      visit(walk, top, c.tet, walk.corner_values(c.tet, 0), 0, c.positive, static_cast<uint8_t>(r), 0,
                            seed_level, &seeds, kInf, 0));
      }
    }
    absorb(top);
    run_parallel(static_cast<int64_t>(seeds.size()), [&](Walk& walk, Worker& w, int64_t i) {
      const Seed& s = seeds[static_cast<size_t>(i)];
      w.table.add(s.parent_key, s.parent_tie,
                  visit(walk, w, s.tet, s.values, s.level, s.positive, s.root, s.path, -1, nullptr, s.parent_key,
                        s.parent_tie));
    });
    finish_pass();
  }

  void next(double bound) {
    bound_ = bound;
    // Chunks of the frontier's lists, each of at most kDescents items to descend (the work) and
    // kChunk items in all; each compacts what it keeps in place. A list holds its items in runs
    // of depth-first order, so the items a pass descends (the finer detail of one region) can lie
    // together: chunks of a fixed length left most of a pass to one thread (at 2048^3, 0.7 s of
    // a 1 M budget's search on one core).
    struct Chunk {
      size_t list, begin, end, kept = 0;
    };
    std::vector<Chunk> chunks;
    constexpr size_t kDescents = 64, kChunk = 4096;
    for (size_t l = 0; l < frontier_.size(); ++l) {
      const std::vector<FrontierItem>& list = frontier_[l];
      size_t begin = 0, descents = 0;
      for (size_t j = 0; j < list.size(); ++j) {
        descents += list[j].key >= bound_;
        if (descents == kDescents || j + 1 - begin == kChunk) {
          chunks.push_back({l, begin, j + 1});
          begin = j + 1, descents = 0;
        }
      }
      if (begin < list.size()) chunks.push_back({l, begin, list.size()});
    }
    run_parallel(static_cast<int64_t>(chunks.size()), [&](Walk& walk, Worker& w, int64_t i) {
      Chunk& c = chunks[static_cast<size_t>(i)];
      std::vector<FrontierItem>& list = frontier_[c.list];
      size_t out = c.begin;
      // The way down to the last item descended: items in a list come in depth-first order, so
      // the next one shares most of it, and only the levels below the first different bit are
      // bisected again.
      std::array<traversal::Child, FrontierItem::kRootShift> way;  // by level, at most 57
      uint64_t way_path = 0;
      int way_level = -1;
      uint8_t way_root = 0;
      for (size_t j = c.begin; j < c.end; ++j) {
        const FrontierItem item = list[j];
        if (!(item.key >= bound_)) {
          list[out++] = item;
          continue;
        }
        const uint8_t root = item.root();
        const int level = item.level();
        const uint64_t path = item.path();
        int from = 0;
        if (way_level >= 0 && root == way_root) from = std::min({std::countr_zero(path ^ way_path), level, way_level});
        if (from == 0) way[0] = roots_[root];
        for (int l = from; l < level; ++l) {
          const traversal::Child& up = way[static_cast<size_t>(l)];
          way[static_cast<size_t>(l) + 1] = traversal::bisect(up.tet, l, up.positive)[(path >> l) & 1];
        }
        way_path = path, way_level = level, way_root = root;
        const traversal::Child& at = way[static_cast<size_t>(level)];
        const Corners f = walk.corner_values(at.tet, level);
        descend(walk, w, at.tet, f, level, at.positive, root, path, item.key, walk.triangles(at.tet, f, at.positive),
                -1, nullptr);
      }
      c.kept = out - c.begin;
    });
    // Close the gaps the chunks left, list by list.
    size_t c = 0;
    for (size_t l = 0; l < frontier_.size(); ++l) {
      size_t end = 0;
      for (; c < chunks.size() && chunks[c].list == l; ++c) {
        const auto from = frontier_[l].begin() + static_cast<std::ptrdiff_t>(chunks[c].begin);
        if (end != chunks[c].begin)  // a chunk already in place stays (std::move may not overlap it)
          std::move(from, from + static_cast<std::ptrdiff_t>(chunks[c].kept),
                    frontier_[l].begin() + static_cast<std::ptrdiff_t>(end));
        end += chunks[c].kept;
      }
      frontier_[l].resize(end);
      if (end < frontier_[l].capacity() / 4) frontier_[l].shrink_to_fit();
    }
    std::erase_if(frontier_, [](const std::vector<FrontierItem>& v) { return v.empty(); });
    finish_pass();
  }

 private:
  static constexpr double kInf = std::numeric_limits<double>::infinity();
  using Corners = std::array<float, 4>;
  struct Seed {
    traversal::PackedTet tet;
    Corners values;
    int level;
    bool positive;
    uint8_t root;
    uint64_t path;
    double parent_key;
    int parent_tie;
  };
  struct Worker {
    KeyTable table;
    // New items of this pass, in blocks of a fixed size: a growing vector would copy them.
    std::vector<std::vector<FrontierItem>> frontier;
    void push(const FrontierItem& item) {
      constexpr size_t kBlock = size_t{1} << 16;
      if (frontier.empty() || frontier.back().size() == kBlock) {
        frontier.emplace_back();
        frontier.back().reserve(kBlock);
      }
      frontier.back().push_back(item);
    }
  };

  // body(walk, worker, i) for i in [0, n), each worker with a walk (a reader) of its own.
  template <class Body>
  void run_parallel(int64_t n, const Body& body) {
    const int64_t workers = std::clamp<int64_t>(static_cast<int64_t>(workers_.size()), 1, std::max<int64_t>(n, 1));
    std::atomic<int64_t> next{0};
    parallel_for(int64_t{0}, workers, [&](int64_t k) {
      Walk walk(source_, rule_);
      Worker& w = workers_[static_cast<size_t>(k)];
      for (int64_t i = next++; i < n; i = next++) {
        throw_if_cancelled(rule_.options());
        body(walk, w, i);
      }
    });
  }
  void absorb(Worker& w) {
    table_.merge(w.table);
    for (std::vector<FrontierItem>& block : w.frontier) frontier_.push_back(std::move(block));
    w.frontier.clear();
  }
  void finish_pass() {
    for (Worker& w : workers_) absorb(w);
    largest_below_ = -kInf;
    for (const std::vector<FrontierItem>& list : frontier_)
      for (const FrontierItem& item : list) largest_below_ = std::max(largest_below_, item.key);
  }

  // The triangles of t itself (0 when culled); t's descent goes into w.
  // `f`: the values at t's corners, handed down from its parent.
  int64_t visit(Walk& walk, Worker& w, const traversal::PackedTet& t, const Corners& f, int level, bool positive,
                uint8_t root, uint64_t path, int seed_level, std::vector<Seed>* seeds, double parent_key,
                int parent_tie) {
    if (seeds && level == seed_level) {
      seeds->push_back({t, f, level, positive, root, path, parent_key, parent_tie});
      return 0;  // counted by the seed's own task
    }
    double key = 0;
    const auto fate = judge_(walk, t, level, &key);
    if (fate == Walk::Fate::culled) return 0;
    const int64_t tris = walk.triangles(t, f, positive);
    // Outside the sample: t counts on the cuts above it, exactly, and not below.
    if (level == sample_.level && !sample_.exact() && !sample_.keeps(root, path)) return tris;
    // A key of -infinity is never split (choose_delta_for_budget: no critical point below).
    if (fate != Walk::Fate::split_key || !(key > -kInf)) return tris;
    if (!(key >= bound_)) {
      w.push(FrontierItem::at(key, root, level, path));
      return tris;
    }
    descend(walk, w, t, f, level, positive, root, path, key, tris, seed_level, seeds);
    return tris;
  }
  void descend(Walk& walk, Worker& w, const traversal::PackedTet& t, const Corners& f, int level, bool positive,
               uint8_t root, uint64_t path, double key, int64_t tris, int seed_level, std::vector<Seed>* seeds) {
    int64_t children = 0;
    const auto cs = traversal::bisect(t, level, positive);
    // A child's corners: three of t's and the midpoint, the one value to read.
    const traversal::Packed mid = (t[0] + t[1]) >> 1;
    const float at_mid = walk.node_value(mid, level + 1);
    const int tie = ties_ ? traversal::SplitRule::tie_class(mid, level) : 0;
    for (uint64_t i = 0; i < 2; ++i) {
      Corners g;
      for (int c = 0; c < 4; ++c) {
        const traversal::Packed p = cs[i].tet[static_cast<size_t>(c)];
        g[static_cast<size_t>(c)] = p == mid ? at_mid : p == t[0] ? f[0] : p == t[1] ? f[1] : p == t[2] ? f[2] : f[3];
      }
      children += visit(walk, w, cs[i].tet, g, level + 1, cs[i].positive, root, path | (i << level), seed_level, seeds,
                        key, tie);
    }
    // Below the sample's level, each subtree kept stands for 2^bits.
    const int64_t weight = !sample_.exact() && level >= sample_.level ? int64_t{1} << sample_.bits : 1;
    w.table.add(key, tie, weight * (children - tris));
  }

  const Source& source_;
  const traversal::SplitRule& rule_;
  const bool ties_;
  const Key& judge_;
  const BudgetSample sample_;
  double bound_ = kInf;
  std::vector<traversal::Child> roots_;
  KeyTable table_;
  std::vector<std::vector<FrontierItem>> frontier_;
  double largest_below_ = -kInf;
  std::vector<Worker> workers_;
};

}  // namespace budget_detail

template <TraversalSource Source, class Key>
BudgetChoice choose_cut_for_budget(const Source& source, const traversal::SplitRule& rule, int64_t max_triangles,
                                   bool ties, const Key& judge, BudgetSample sample) {
  constexpr double kInf = std::numeric_limits<double>::infinity();
  // Subtrees for the threads in the first pass: a few thousand at most, as the extraction's pieces.
  const int seed_level = std::min(source.lattice().max_level(), 9);
  if (sample.bits < 1 || sample.level < sample.bits || sample.level >= source.lattice().max_level()) sample = {};
  const bool sampled = !sample.exact();
  // What the steps must not exceed: the budget itself, or where a sample aims within it.
  const int64_t limit = sampled ? static_cast<int64_t>(kSampleAim * static_cast<double>(max_triangles)) : max_triangles;
  budget_detail::CountPasses<Source, Key> passes(source, rule, ties, judge, sample);
  double bound = kInf;
  for (bool first = true;; first = false) {
    if (first)
      passes.first(bound, seed_level);
    else
      passes.next(bound);
    // T at every key >= bound, from +infinity down, each key's tie classes coarse to fine.
    struct Step {
      double key;
      int tie;
      int64_t delta;
    };
    std::vector<Step> d;
    d.reserve(passes.d().size());
    passes.d().for_each([&](const budget_detail::TieKey& k, int64_t v) { d.push_back({k.key, k.tie, v}); });
    std::sort(d.begin(), d.end(),
              [](const Step& a, const Step& b) { return a.key != b.key ? a.key > b.key : a.tie < b.tie; });
    const double largest_below = passes.largest_below();
    size_t i = 0;
    int64_t count = 0;
    for (; i < d.size() && d[i].key == kInf; ++i) count += d[i].delta;
    const int64_t infinite = count;
    if (sampled && count > limit) {
      BudgetChoice none;
      none.sampled = true, none.fits = false;
      return none;
    }
    if (count > max_triangles) {
      const TopologyMode mode = rule.options().topology;
      throw TriangleBudgetTooSmall(
          "a budget of " + std::to_string(max_triangles) +
          " triangles is below the coarsest mesh this topology mode allows (" + std::to_string(count) + " triangles)" +
          (mode == TopologyMode::preserve || mode == TopologyMode::paper
               ? "; topology mode simplify with a budget and no delta drops the smallest features to fit"
               : ""));
    }
    const bool more_below = largest_below > -kInf;
    BudgetChoice choice;
    choice.sampled = sampled;
    choice.triangles = count;
    // The largest finite key: the first one the walk down from +infinity meets.
    choice.eps = i < d.size() ? std::nextafter(d[i].key, kInf) : more_below ? std::nextafter(largest_below, kInf) : 0;
    // T at the keys >= bound, in decreasing order: each key, and within it each tie class but its
    // last (after which the cut is "key >= eps": ties -1), is one step finer.
    for (; i < d.size(); ++i) {
      count += d[i].delta;
      ++choice.steps;
      const int tie = i + 1 < d.size() && d[i + 1].key == d[i].key ? d[i].tie + 1 : -1;
      if (count > limit) {
        choice.next_eps = d[i].key;
        choice.next_ties = tie;
        choice.next_triangles = count;
        return choice;
      }
      choice.eps = d[i].key;
      choice.ties = tie;
      choice.triangles = count;
    }
    if (!more_below) {
      choice.eps = 0;  // everything refined: the full-resolution mesh
      return choice;
    }
    // Every key >= bound fits: lower the bound, at most 4x a pass so that no pass descends far
    // beyond the cut asked for. Below the keys of +infinity (what the topology mode refines
    // whatever eps is), T grows about as a power of 1/eps: fit it locally, to T at the smallest
    // key known and at the smallest key at least 1.5 times that, and aim above the budget: a pass
    // that stops short costs the next one (it resumes where the last stopped, but walks down to
    // its frontier and reads those bricks again), one that goes too far descends what no cut
    // needs. An exact search aims at 1.25x; a sample descends 1 / 2^bits of what lies below its
    // level, so going too far costs less and it aims at 2x (at 1024^3, 300 k to 2 M triangles:
    // 2-10% faster for the process; on embryo's exact search, 2x was 23% slower).
    const double x = !d.empty() && d.back().key < kInf ? d.back().key : largest_below;
    double lowest = x / 4;
    if (!d.empty() && x == d.back().key && count > infinite) {
      double x2 = 0;
      int64_t at_x2 = 0, sum = 0;
      for (const Step& s : d) {  // a key's classes are adjacent: x2's sum ends with its last
        if (s.key < 1.5 * x) break;
        sum += s.delta;
        if (s.key < kInf) x2 = s.key, at_x2 = sum;
      }
      if (x2 > x && at_x2 > infinite && count > at_x2) {
        const double grown = static_cast<double>(count - infinite), before = static_cast<double>(at_x2 - infinite);
        const double exponent = std::log(grown / before) / std::log(x2 / x);
        const double target = (sampled ? 2.0 : 1.25) * static_cast<double>(limit - infinite);
        lowest = std::clamp(x * std::pow(grown / target, 1.0 / exponent), x / 4, x / 1.25);
      }
    }
    bound = std::min(lowest, largest_below);
  }
}

}  // namespace isotope
