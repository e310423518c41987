#pragma once
// The adaptive traversal (paper Sec. 3.2 with the stopping rule of docs/METHOD.md), generic over where
// values and records come from: any TraversalSource (a C++20 concept), a
// hierarchy in memory or a store paged through a brick cache.
#include <algorithm>
#include <array>
#include <cassert>
#include <cmath>
#include <cstdint>
#include <limits>
#include <memory>
#include <utility>
#include <vector>

#include "engine/extract/options.h"
#include "engine/extract/traversal_source.h"
#include "engine/hierarchy/kuhn.h"
#include "engine/hierarchy/lattice.h"
#include "engine/hierarchy/record.h"
#include "engine/mesh/box_clip.h"
#include "engine/mesh/marching_tetrahedra.h"

namespace isotope {

namespace traversal {

using PackedTet = std::array<Packed, 4>;

inline int64_t orientation(const Tet& c) {
  const int64_t ax = c[1][0] - c[0][0], ay = c[1][1] - c[0][1], az = c[1][2] - c[0][2];
  const int64_t bx = c[2][0] - c[0][0], by = c[2][1] - c[0][1], bz = c[2][2] - c[0][2];
  const int64_t cx = c[3][0] - c[0][0], cy = c[3][1] - c[0][1], cz = c[3][2] - c[0][2];
  return ax * (by * cz - bz * cy) - ay * (bx * cz - bz * cx) + az * (bx * cy - by * cx);
}

// Bisecting t at level `level` (`positive`: its corners in this order span a positively oriented
// tetrahedron). The first child keeps the orientation; the second too at level mod 3 == 0, and is
// mirrored otherwise (its corners are an odd permutation of the parent's, up to the midpoint).
struct Child {
  PackedTet tet;
  bool positive;
};
inline std::array<Child, 2> bisect(const PackedTet& t, int level, bool positive) {
  const Packed v = (t[0] + t[1]) >> 1;
  if (level % 3 == 0) return {{{{t[0], t[2], t[3], v}, positive}, {{t[1], t[3], t[2], v}, positive}}};
  return {{{{t[0], t[2], t[3], v}, positive}, {{t[1], t[2], t[3], v}, !positive}}};
}
// The values at the corners of bisect's children, in their corners' order, from those of t
// (`f`, in t's order) and the value at its refinement vertex.
inline std::array<std::array<float, 4>, 2> bisect_values(const std::array<float, 4>& f, float at_v, int level) {
  if (level % 3 == 0) return {{{f[0], f[2], f[3], at_v}, {f[1], f[3], f[2], at_v}}};
  return {{{f[0], f[2], f[3], at_v}, {f[1], f[2], f[3], at_v}}};
}

// Triangles marching tetrahedra makes of one tetrahedron (as TetCutter cuts it).
inline int triangles_of(const std::array<float, 4>& f, float iso) {
  const int above = (f[0] > iso) + (f[1] > iso) + (f[2] > iso) + (f[3] > iso);
  return above == 2 ? 2 : (above == 1 || above == 3) ? 1 : 0;
}

// When a diamond is refined. Each diamond v gets a split key: +inf when its topology forbids
// stopping there, else its error divided by the focus factor g(v) in [0, 1]; a tetrahedron
// bisected at v is refined iff key >= eps. Keys never grow from a diamond to its children
// (errors and critical flags are saturated, g never shrinks), which keeps the mesh conforming
// (crack-free) for any eps and makes "refine everything with key >= eps" a cut of the tree that
// moves down monotonically as eps falls (choose_eps_for_budget relies on this).
class SplitRule {
 public:
  // error_fold: added to every error before it is compared (a quantized store's rounding,
  // docs/FORMAT.md, "Quantization"): the records are those of the quantized field.
  SplitRule(const ExtractCall& o, const Lattice& lattice, const std::array<double, 3>& origin,
            const std::array<double, 3>& spacing, double error_fold = 0)
      : options_(o), origin_(origin), spacing_(spacing), fold_(error_fold) {
    fields_.exact = o.topology == TopologyMode::preserve || o.topology == TopologyMode::simplify;
    fields_.weights = o.topology == TopologyMode::simplify;
    fields_.paper = o.topology == TopologyMode::paper;
    fields_.surplus = o.error == ErrorIndicator::surplus;
    if (!o.focus) return;
    // Focus: g(v) = clamp(d(v) / R, 0, 1), d(v) = |v - focus| - reach(level). reach(l) is the sum
    // of the longest edges of all finer levels, so d(child) >= d(parent) by the triangle
    // inequality (a child diamond's centre lies within one such edge of its parent's centre).
    const double h = std::max({spacing[0], spacing[1], spacing[2]});
    reach_.assign(static_cast<size_t>(lattice.max_level() + 1), 0.0);
    for (int l = lattice.max_level() - 1; l >= 0; --l)
      reach_[static_cast<size_t>(l)] = reach_[static_cast<size_t>(l) + 1] + longest_edge(l + 1, lattice, h);
  }

  double key(const DiamondBounds& b, const DiamondTopology& t, Packed v, int level) const {
    return critical(t) ? std::numeric_limits<double>::infinity() : error_key(b, v, level);
  }
  // The key as far as the error goes: key = error_key unless critical(). The traversal reads the
  // topology record only when this alone would let it stop (docs/METHOD.md: most visits never do).
  double error_key(const DiamondBounds& b, Packed v, int level) const {
    const double err = (options_.error == ErrorIndicator::bound ? b.error_bound : b.error_surplus) + fold_;
    if (reach_.empty()) return err;
    const double g = focus_factor(v, level);
    return g > 0 ? err / g : std::numeric_limits<double>::infinity();
  }
  bool critical(const DiamondTopology& t) const {
    const float iso = options_.iso;
    switch (options_.topology) {
      case TopologyMode::none: return false;
      case TopologyMode::paper: return t.paper_lo <= iso && iso < t.paper_hi;
      case TopologyMode::preserve: return exact_fires(t);
      case TopologyMode::simplify: return exact_fires(t) && heavy(t);
    }
    return false;
  }
  // The chosen weight of v's diamond where the exact rule fires at the isovalue below it, else
  // -infinity.
  double topology_weight(const DiamondTopology& t) const {
    return exact_fires(t) ? static_cast<double>(t.weight[static_cast<size_t>(options_.weight)])
                          : -std::numeric_limits<double>::infinity();
  }
  // Simplify mode: the exact rule fires below, but its weight is under delta.
  bool dropped(const DiamondTopology& t) const {
    return options_.topology == TopologyMode::simplify && exact_fires(t) && !heavy(t);
  }
  // Whether a diamond whose key (or error key) is `key` is refined: key >= eps, where a key equal to
  // eps refines only the tie classes below eps_ties when those are given. Classes grow downwards
  // (a child's level is its parent's plus one), so the rule still refines every refined diamond's
  // parents, as key >= eps alone does.
  bool refines(double key, Packed v, int level) const {
    if (key != options_.eps || options_.eps_ties < 0) return key >= options_.eps;
    return tie_class(v, level) < options_.eps_ties;
  }
  // Level-major, then one of kTieBuckets buckets by a hash of the diamond's centre.
  static int tie_class(Packed v, int level) {
    static_assert(kTieBuckets == 16, "the bucket is the hash's top 4 bits");
    return level * kTieBuckets + static_cast<int>((v * 0x9E3779B97F4A7C15ull) >> 60);
  }
  bool in_range(const DiamondBounds& b) const { return b.lo <= options_.iso && options_.iso < b.hi; }
  const ExtractCall& options() const { return options_; }
  // The fields error_key(), critical() and dropped() read beyond the range and the bound.
  const RecordFields& fields() const { return fields_; }

 private:
  bool exact_fires(const DiamondTopology& t) const { return t.exact_lo <= options_.iso && options_.iso < t.exact_hi; }
  bool heavy(const DiamondTopology& t) const {
    return static_cast<double>(t.weight[static_cast<size_t>(options_.weight)]) >= options_.delta;
  }
  // Of a level-l tetrahedron: its refinement edge, a diagonal of a cube, of a face, or an edge.
  static double longest_edge(int l, const Lattice& lattice, double h) {
    const double longest[3] = {std::sqrt(3.0), std::sqrt(2.0), 1.0};
    return std::ldexp(h, lattice.k - l / 3) * longest[l % 3];
  }
  double focus_factor(Packed v, int level) const {
    const Coord c = unpack(v);
    double d2 = 0;
    for (int a = 0; a < 3; ++a) {
      const double x = origin_[a] + spacing_[a] * static_cast<double>(c[a]) - options_.focus->point[a];
      d2 += x * x;
    }
    const double d = std::sqrt(d2) - reach_[static_cast<size_t>(level)];
    return std::clamp(d / options_.focus->radius, 0.0, 1.0);
  }

  ExtractCall options_;
  std::array<double, 3> origin_, spacing_;
  double fold_ = 0;
  RecordFields fields_;
  std::vector<double> reach_;  // per level; empty without a focus
};

// An array that grows without initializing: the levels' tetrahedra are written before read.
template <class T>
class Scratch {
 public:
  void reserve(size_t n) {
    if (n <= capacity_) return;
    capacity_ = std::max(n, 2 * capacity_);
    data_ = std::make_unique_for_overwrite<T[]>(capacity_);
  }
  T& operator[](size_t i) { return data_[i]; }

 private:
  std::unique_ptr<T[]> data_;
  size_t capacity_ = 0;
};

// What a level-by-level walk holds (Traversal::visit_by_levels): the roots of the chunks of levels
// still to walk, and one level of a chunk and the next. Lent from piece to piece
// (LendingPool), it is memory touched about once per extraction, where one per traversal was fresh
// memory every piece (docs/METHOD.md, "In parallel").
template <TraversalSource Source>
struct LevelScratch {
  struct Root {
    Child tet;
    // At its corners, when the walk carries them (Traversal::kCarryValues); NaN: not read yet.
    std::array<float, 4> values;
    int level;
  };
  std::vector<Root> roots;  // of the chunks still to walk, the next one last
  Scratch<Child> frontier, next;
  Scratch<std::array<float, 4>> frontier_values, next_values;  // at the corners of frontier and next, when carried
  Scratch<typename Source::Reader::Handle> handles;            // of frontier
  // Of frontier and next: the tetrahedron reaches past the data box (Traversal::past_box). Else no
  // tetrahedron below it does, and the walk does not ask again.
  Scratch<uint8_t> frontier_near, next_near;
  // The welding table of the traversal's mesh (MeshBuilder): lent with the rest, it keeps the memory
  // of the largest piece's, emptied in O(1), where a table per piece was allocated anew each time.
  EdgeVertexMap welds{0};
};

// A piece of the traversal: a subtree to descend, or one tetrahedron to emit.
struct Piece {
  PackedTet tet{};
  int level = 0;
  bool positive = false;
  bool emit_only = false;
};

// Over the bisection tree (depth first down to the pieces, level by level within each): cull by
// range, stop by the split rule, emit at stopping tetrahedra and at the leaves.
template <TraversalSource Source>
class Traversal {
 public:
  // levels: scratch for visit_by_levels lent for this traversal's life (LendingPool), or null.
  Traversal(const Source& source, const SplitRule& rule, LevelScratch<Source>* levels = nullptr)
      : reader_(source.reader()),
        lattice_(source.lattice()),
        rule_(rule),
        builder_(rule.options().iso, lattice_.side, source.origin(), source.spacing(),
                 levels ? &levels->welds : nullptr),
        box_(BoxClip::of(source.data_dims(), lattice_.n, source.origin(), source.spacing())),
        clip_(box_.any()),
        levels_(levels) {
    for (int i = 0; i < 3; ++i) box_max_[i] = source.data_dims()[i] - 1;
  }

  // The traversal cut at `level` into pieces, in depth-first order: the subtrees rooted there and
  // the tetrahedra emitted above it. Running the pieces in this order is the whole traversal.
  std::vector<Piece> split(int level) {
    std::vector<Piece> pieces;
    pieces_ = &pieces;
    split_level_ = level;
    for (const auto& [root, positive] : roots()) visit(root, 0, positive);
    pieces_ = nullptr;
    return pieces;
  }

  std::vector<Child> roots() const {
    std::vector<Child> out;
    const int64_t n = lattice_.n;
    for (const Tet& r : kuhn_tetrahedra({0, 0, 0}, {n, n, n}))
      out.push_back({{pack(r[0]), pack(r[1]), pack(r[2]), pack(r[3])}, orientation(r) > 0});
    return out;
  }

  // A cost estimate of running piece p (isotope/distribution.h): how many subtrees of
  // `level` below it the traversal reaches (cull and stop as run() would above that level),
  // reading only the records of the levels above. An emitting piece costs 1.
  int64_t reach(const Piece& p, int level) {
    if (p.emit_only) return 1;
    std::vector<Piece> below;
    pieces_ = &below;
    split_level_ = level;
    visit(p.tet, p.level, p.positive);
    pieces_ = nullptr;
    return static_cast<int64_t>(below.size());
  }

  void run(const Piece& p) {
    if (p.emit_only)
      emit(p.tet, p.level, p.positive);
    else
      visit_by_levels(p.tet, p.level, p.positive);
  }

  // What the traversal decides about one tetrahedron, without descending: used by the budget
  // search, which walks the same tree in another order.
  enum class Fate { culled, leaf, split_key };
  Fate judge(const PackedTet& t, int level, double* key) {
    if (clip_ && outside_box(t)) return Fate::culled;
    if (level == lattice_.max_level()) return Fate::leaf;
    const Packed v = (t[0] + t[1]) >> 1;
    const auto h = reader_.locate(v);
    const DiamondBounds b = reader_.bounds(h, rule_.fields());
    if (!rule_.in_range(b)) return Fate::culled;
    *key = rule_.key(b, reader_.topology(h, rule_.fields()), v, level);
    return Fate::split_key;
  }
  // For the choice of delta (choose_delta_for_budget): the fate as judge's, the error's part of
  // the key, and `weight`: the diamond's saturated weight when the exact rule fires at the
  // isovalue below it, else -infinity (never split for its topology).
  Fate judge_topology(const PackedTet& t, int level, double* error_key, double* weight) {
    if (clip_ && outside_box(t)) return Fate::culled;
    if (level == lattice_.max_level()) return Fate::leaf;
    const Packed v = (t[0] + t[1]) >> 1;
    const auto h = reader_.locate(v);
    const DiamondBounds b = reader_.bounds(h, rule_.fields());
    if (!rule_.in_range(b)) return Fate::culled;
    *error_key = rule_.error_key(b, v, level);
    *weight = rule_.topology_weight(reader_.topology(h, rule_.fields()));
    return Fate::split_key;
  }
  // The triangles the mesh will have of t if it stops there, from the values at its corners:
  // marching tetrahedra's, clipped to the data box where t reaches past it (clipped_triangles),
  // as the extraction clips its mesh.
  int triangles(const PackedTet& t, const std::array<float, 4>& f, bool positive) const {
    const int n = triangles_of(f, rule_.options().iso);
    if (n == 0 || !clip_ || !past_box(t)) return n;
    return clipped_triangles(box_, builder_.cutter(), {unpack(t[0]), unpack(t[1]), unpack(t[2]), unpack(t[3])}, f,
                             positive);
  }
  int triangles(const PackedTet& t, int level, bool positive) {
    return triangles(t, corner_values(t, level), positive);
  }
  // The values marching tetrahedra reads at a level-`level` tetrahedron's corners, and at one
  // node of such a tetrahedron (a node's value does not depend on the level it is read at).
  std::array<float, 4> corner_values(const PackedTet& t, int level) {
    const int j = band_of(level);
    return {value(t[0], j), value(t[1], j), value(t[2], j), value(t[3], j)};
  }
  float node_value(Packed p, int level) { return value(p, band_of(level)); }

  void keep_keys() { builder_.keep_keys(); }
  std::vector<uint64_t> take_keys() { return builder_.take_keys(); }
  Mesh take() { return builder_.take(); }
  int64_t tets_visited() const { return tets_visited_; }
  int64_t tets_emitted() const { return tets_emitted_; }
  int64_t tets_simplified() const { return tets_simplified_; }

 private:
  enum class Step { cull, stop, refine };
  // What the traversal does at t: cull it (no value on each side, or beyond the data box), stop
  // and emit it, or refine it.
  using Handle = typename Source::Reader::Handle;
  // Whether the reader gives the value of the node whose record a handle locates
  // (value_at_record): then a level-by-level walk carries its tetrahedra's corner values down, each
  // child reading only its new corner, the parent's refinement vertex, beside the record just read,
  // and a stopping tetrahedron none. A subtree's own corners start unread (NaN) and are read at a
  // stop that needs them, so the walk reads no brick it did not read before. A source whose values
  // are one array lookup away (MultiresVolume) reads the four at the stop instead, which costs it
  // less than carrying them (docs/METHOD.md, "In parallel").
  static constexpr bool kCarryValues = requires(typename Source::Reader & r, const Handle& h) { r.value_at_record(h); };
  static constexpr float kUnread = std::numeric_limits<float>::quiet_NaN();  // no value is NaN
  // h: where the record of t's refinement vertex lives (unused at the leaves).
  // near: t may lie beyond the data box (only a tetrahedron that reaches past it can).
  Step step(const PackedTet& t, int level, const Handle& h, bool near) {
    ++tets_visited_;
    if (near && outside_box(t)) return Step::cull;
    if (level == lattice_.max_level()) return Step::stop;
    const DiamondBounds b = reader_.bounds(h, rule_.fields());
    if (!rule_.in_range(b)) return Step::cull;
    const Packed v = (t[0] + t[1]) >> 1;
    if (!rule_.refines(rule_.error_key(b, v, level), v, level)) {
      if (!rule_.fields().topology()) return Step::stop;  // topology none: nothing more to read
      const DiamondTopology topology = reader_.topology(h, rule_.fields());
      if (!rule_.critical(topology)) {
        tets_simplified_ += rule_.dropped(topology);
        return Step::stop;
      }
    }
    return Step::refine;
  }
  // Beyond the data box there may be no record to locate: step() culls such a tetrahedron
  // before it reads the handle.
  Handle locate(const PackedTet& t, int level) {
    if (level == lattice_.max_level() || (clip_ && outside_box(t))) return Handle{};
    return reader_.locate((t[0] + t[1]) >> 1);
  }

  void visit(const PackedTet& t, int level, bool positive) {
    if (pieces_ && level == split_level_) return pieces_->push_back({t, level, positive, false});
    switch (step(t, level, locate(t, level), clip_)) {
      case Step::cull: return;
      case Step::stop: return emit(t, level, positive);
      case Step::refine:
        for (const Child& c : bisect(t, level, positive)) visit(c.tet, level + 1, c.positive);
    }
  }

  // The subtree of t level by level, not depth first: a whole level's records are asked for
  // before any is read, so their cache misses overlap instead of queuing one behind the other. The
  // levels go in chunks of kChunkLevels: the tetrahedra a chunk reaches at its last level are the
  // roots of the next chunks, walked depth first, so that a chunk stays within a region a few
  // bricks across however large the subtree (docs/METHOD.md, "In parallel"), and the order depends
  // on the tree alone, not on which tetrahedra were culled. The same tetrahedra stop and are
  // emitted as in visit(), in another order. A tetrahedron within the data box has its children
  // within it too: the walk tests for the box only below those that reach past it (`near`), a
  // few along the box's far faces, instead of at every tetrahedron.
  static constexpr int kChunkLevels = 12;
  void visit_by_levels(const PackedTet& t, int level, bool positive) {
    LevelScratch<Source>& s = levels_ ? *levels_ : own_levels_;
    s.roots.clear();
    s.roots.push_back({Child{t, positive}, {}, level});
    if constexpr (kCarryValues) s.roots.back().values = {kUnread, kUnread, kUnread, kUnread};
    while (!s.roots.empty()) {
      const auto root = s.roots.back();
      s.roots.pop_back();
      s.frontier.reserve(1);
      s.frontier[0] = root.tet;
      s.frontier_near.reserve(1);
      s.frontier_near[0] = clip_ && past_box(root.tet.tet);
      if constexpr (kCarryValues) {
        s.frontier_values.reserve(1);
        s.frontier_values[0] = root.values;
      }
      size_t n = 1;
      int l = root.level;
      // Chunks end where a whole number of them reaches just past the finest level, so that the
      // last one holds the finest levels whole.
      const int end = root.level + 1 + (lattice_.max_level() - root.level) % kChunkLevels;
      for (; n > 0 && l < end; ++l) {
        s.handles.reserve(n);
        s.next.reserve(2 * n);  // written by index: a refined tetrahedron has two children
        s.next_near.reserve(2 * n);
        if constexpr (kCarryValues) s.next_values.reserve(2 * n);
        if (l < lattice_.max_level())
          for (size_t i = 0; i < n; ++i) {
            if (s.frontier_near[i] && outside_box(s.frontier[i].tet)) continue;  // see locate() below
            s.handles[i] = reader_.locate((s.frontier[i].tet[0] + s.frontier[i].tet[1]) >> 1);
            reader_.prefetch(s.handles[i]);
          }
        size_t next = 0;
        for (size_t i = 0; i < n; ++i) {
          const Child& c = s.frontier[i];
          const bool near = s.frontier_near[i];
          switch (step(c.tet, l, s.handles[i], near)) {
            case Step::cull: break;
            case Step::stop:
              if constexpr (kCarryValues)
                emit_carried(c.tet, l, s.frontier_values[i], c.positive);
              else
                emit(c.tet, l, c.positive);
              break;
            case Step::refine: {
              const auto children = bisect(c.tet, l, c.positive);
              if constexpr (kCarryValues) {
                const auto values = bisect_values(s.frontier_values[i], reader_.value_at_record(s.handles[i]), l);
                s.next_values[next] = values[0];
                s.next_values[next + 1] = values[1];
              }
              s.next_near[next] = near && past_box(children[0].tet);
              s.next_near[next + 1] = near && past_box(children[1].tet);
              s.next[next++] = children[0];
              s.next[next++] = children[1];
            }
          }
        }
        std::swap(s.frontier, s.next);
        std::swap(s.frontier_values, s.next_values);
        std::swap(s.frontier_near, s.next_near);
        n = next;
      }
      for (size_t i = n; i-- > 0;) {  // the first on top
        s.roots.push_back({s.frontier[i], {}, l});
        if constexpr (kCarryValues) s.roots.back().values = s.frontier_values[i];
      }
    }
  }

  // Some corner of the tetrahedron lies beyond a face of the data box.
  bool past_box(const PackedTet& t) const {
    for (int a = 0; a < 3; ++a) {
      const int shift = a * kFieldBits;
      for (Packed p : t)
        if (static_cast<int64_t>((p >> shift) & kFieldMask) > box_max_[a]) return true;
    }
    return false;
  }
  // The tetrahedron lies in a half-space beyond a face of the data box: it meets the box in a
  // face at most. Leaves are unit-cell Kuhn tetrahedra, wholly inside or caught here.
  bool outside_box(const PackedTet& t) const {
    for (int a = 0; a < 3; ++a) {
      const int shift = a * kFieldBits;
      Packed lo = kFieldMask;
      for (Packed p : t) lo = std::min(lo, (p >> shift) & kFieldMask);
      if (static_cast<int64_t>(lo) >= box_max_[a]) return true;
    }
    return false;
  }

  float value(Packed p, int j) { return reader_.value(unpack(p), j); }
  // The corners of a level-l tetrahedron lie on G_j for this j (its refinement vertex has scale j).
  int band_of(int level) const { return std::max(0, lattice_.k - 1 - level / 3); }

  void emit(const PackedTet& t, int level, bool positive) {
    if (pieces_) return pieces_->push_back({t, level, positive, true});
    emit_values(t, corner_values(t, level), positive);
  }
  // A stop with the values carried down: those of the subtree's own corners still unread are read
  // here, as emit() reads them.
  void emit_carried(const PackedTet& t, int level, std::array<float, 4> f, bool positive) {
    for (int c = 0; c < 4; ++c)
      if (std::isnan(f[static_cast<size_t>(c)])) [[unlikely]]
        f[static_cast<size_t>(c)] = value(t[static_cast<size_t>(c)], band_of(level));
    emit_values(t, f, positive);
  }
  void emit_values(const PackedTet& t, const std::array<float, 4>& f, bool positive) {
    ++tets_emitted_;
    // Most stopping tetrahedra lie in a diamond whose range holds the isovalue but are not cut
    // themselves: settle that before building their corners.
    const int cut = triangles_of(f, rule_.options().iso);
    if (cut == 0) return;
    builder_.add_tet({unpack(t[0]), unpack(t[1]), unpack(t[2]), unpack(t[3])}, f, positive);
  }

  typename Source::Reader reader_;
  const Lattice& lattice_;
  const SplitRule& rule_;
  MeshBuilder builder_;
  BoxClip box_;
  bool clip_;  // box_.any(): the data box is smaller than the lattice
  Coord box_max_{};
  int64_t tets_visited_ = 0, tets_emitted_ = 0, tets_simplified_ = 0;
  std::vector<Piece>* pieces_ = nullptr;  // while splitting
  LevelScratch<Source> own_levels_;
  LevelScratch<Source>* levels_ = nullptr;  // another's, lent for this traversal; else own_levels_
  int split_level_ = 0;
};

}  // namespace traversal
}  // namespace isotope
