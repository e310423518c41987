#include "io/store/paged_volume.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <stdexcept>

#include "engine/core/parallel.h"
#include "engine/extract/adaptive_extract.h"
#include "engine/hierarchy/record_builder.h"

namespace isotope {
namespace {

template <class T>
T load(T* p) {
  return std::atomic_ref<T>(*p).load(std::memory_order_relaxed);
}
template <class T>
void store(T* p, T v) {
  std::atomic_ref<T>(*p).store(v, std::memory_order_relaxed);
}

}  // namespace

PagedVolume::PagedVolume(BrickCache& cache)
    : cache_(cache),
      layout_(cache.store().layout()),
      header_(cache.store().header()),
      indexer_(layout_),
      value_offset_(header_.value_offset),
      value_scale_(header_.value_scale) {
  // Templates from a reference vertex of each class on a large lattice, far from its faces: at
  // scale 0 the shape does not depend on the lattice, and the leaves (children of edge
  // midpoints) are the same levels below.
  Lattice reference;
  reference.k = 10;
  reference.n = 1024;
  reference.side = 1025;
  for (int c = 0; c < 64; ++c) {
    const Coord v{16 + (c & 3), 16 + (c >> 2 & 3), 16 + (c >> 4 & 3)};
    if (((v[0] | v[1] | v[2]) & 1) == 0) continue;  // not of scale 0
    Band0Template& t = band0_templates_[static_cast<size_t>(c)];
    const Diamond d = diamond_of(v, reference);
    auto offset = [&](const Coord& p) {
      return std::array<int8_t, 3>{static_cast<int8_t>(p[0] - v[0]), static_cast<int8_t>(p[1] - v[1]),
                                   static_cast<int8_t>(p[2] - v[2])};
    };
    t.value[0] = offset(d.a), t.value[1] = offset(d.b), t.value[2] = offset(d.v);
    for (int i = 0; i < d.ring_count; ++i) t.value[static_cast<size_t>(3 + i)] = offset(d.ring[i]);
    t.values = 3 + d.ring_count;
    for_each_child(d, reference, [&](const Coord& u) { t.child[static_cast<size_t>(t.children++)] = offset(u); });
    t.type = d.type;
    t.shape = shape_of(d, reference);
    // band0_bounds_inside reads them as nodes of the data box for any vertex inside it by one node.
    for (const auto& o : t.value)
      for (const int8_t x : o)
        if (x < -1 || x > 1) throw std::logic_error("a scale-0 diamond reaches past its vertex's neighbours");
    for (const auto& o : t.child)
      for (const int8_t x : o)
        if (x < -1 || x > 1) throw std::logic_error("a scale-0 diamond's child lies past its vertex's neighbours");
    t.valid = true;
  }
}

Coord PagedVolume::Pager::band0_node(const CachedBrick& brick, uint32_t m) {
  const Box3& o = brick.origin();
  return {o[0] + compact_bits_3(m), o[1] + compact_bits_3(m >> 1), o[2] + compact_bits_3(m >> 2)};
}

float PagedVolume::Pager::value_at(const Coord& c) {
  const auto& dims = volume_->layout_.dims();
  uint32_t m = 0;
  const int64_t index = volume_->indexer_.locate(0, std::min(c[0], dims[0] - 1), std::min(c[1], dims[1] - 1),
                                                 std::min(c[2], dims[2] - 1), &m);
  return brick(index).values()[m];
}

Record PagedVolume::Pager::band0_record(const Coord& v, bool topology) {
  const StoreLayout& layout = volume_->layout_;
  const Lattice& lattice = layout.lattice();
  uint32_t m = 0;
  const int64_t index = volume_->indexer_.locate(0, v[0], v[1], v[2], &m);
  const std::shared_ptr<CachedBrick> home = hold(index);  // alive while the children pin others
  const Diamond d = diamond_of(v, lattice);
  DiamondValues dv;
  DiamondBounds range;
  const bool inside = read_polyhedron(
      d, lattice, layout.dims(), [&](const Coord& c) { return value_at(c); }, dv, range);
  const RecordFields held = fields_held(*home);
  Saturation sat;
  for_each_child(d, lattice, [&](const Coord& u) {
    // Without a record, u's whole diamond lies beyond a face of the data box (as RecordBuilder).
    for (int a = 0; a < 3; ++a)
      if (u[a] > record_extent(lattice, layout.dims(), a, 0)) return;
    uint32_t cm = 0;
    const int64_t ci = volume_->indexer_.locate(0, u[0], u[1], u[2], &cm);
    sat.add(child_record(ci, cm, topology, held), range, topology);
  });
  CriticalCounts unused = {{0, 0, 0}, {0, 0, 0}};
  const Record r = finish_record(dv, shape_for_weights(d, lattice, dv, inside, topology, held.weights), inside, range,
                                 sat, unused, topology, nullptr, held.weights);
  store_band0_record(*home, m, r, topology, held);
  return r;
}

RecordFields PagedVolume::Pager::fields_held(const CachedBrick& home) {
  return {home.exact() != nullptr, home.paper() != nullptr, home.weights() != nullptr, home.surplus() != nullptr};
}

Record PagedVolume::Pager::child_record(int64_t index, uint32_t m, bool topology, const RecordFields& held) {
  const PackedBounds p = bounds_of(bounds_word(index, m));
  Record c;
  c.bounds = {bf16_to_float(p.lo), bf16_to_float(p.hi), p.bound,
              held.surplus ? bf16_to_float(this->surplus(index, m)) : 0.0f};
  if (topology) c.topology = this->topology(index, m, {held.exact, held.paper, held.weights, false});
  return c;
}

void PagedVolume::Pager::store_band0_record(CachedBrick& home, uint32_t m, const Record& r, bool topology,
                                            const RecordFields& held) {
  const PackedTopology t = pack_topology(r.topology, r.bounds.error_surplus);
  if (held.surplus) store(home.surplus() + m, t.surplus);
  if (topology) {
    if (held.exact) store(home.exact() + m, interval_word(t.exact_lo, t.exact_hi));
    if (held.paper) store(home.paper() + m, interval_word(t.paper_lo, t.paper_hi));
    if (held.weights) store(home.weights() + m, weights_word(t.weight));
  }
  store_bounds(home, m, pack_bounds(r.bounds));  // last: the word others check first
}

bool PagedVolume::Pager::inside_by_one(const Coord& v) const {
  const auto& dims = volume_->layout_.dims();
  return v[0] >= 1 && v[1] >= 1 && v[2] >= 1 && v[0] + 1 < dims[0] && v[1] + 1 < dims[1] && v[2] + 1 < dims[2];
}

const PagedVolume::Band0Template& PagedVolume::Pager::template_of(const Coord& v) const {
  return volume_->band0_templates_[static_cast<size_t>((v[0] & 3) | (v[1] & 3) << 2 | (v[2] & 3) << 4)];
}

PagedVolume::Pager::Near PagedVolume::Pager::near_of(const Coord& v) const {
  const int64_t mask = volume_->layout_.brick_width() - 1;
  return {v[0] & mask, v[1] & mask, v[2] & mask, mask};
}

DiamondBounds PagedVolume::Pager::polyhedron_values(const Coord& v, const Band0Template& t, const CachedBrick& home,
                                                    const Near& near, float* f) {
  home.values().visit([&](const auto* values) {
    for (int i = 0; i < t.values; ++i) {
      const auto& o = t.value[static_cast<size_t>(i)];
      f[i] = near.in_brick(o) ? static_cast<float>(values[near.index(o)])
                              : value_at({v[0] + o[0], v[1] + o[1], v[2] + o[2]});
    }
  });
  DiamondBounds range{f[0], f[0], 0, 0};
  for (int i = 1; i < t.values; ++i) range.lo = std::min(range.lo, f[i]), range.hi = std::max(range.hi, f[i]);
  return range;
}

PagedVolume::Pager::Slot PagedVolume::Pager::slot_near(const Coord& v, const std::array<int8_t, 3>& o, int64_t index,
                                                       const Near& near) const {
  if (near.in_brick(o)) return {index, near.index(o), true};
  Slot s{0, 0, false};
  s.index = volume_->indexer_.locate(0, v[0] + o[0], v[1] + o[1], v[2] + o[2], &s.m);
  return s;
}

Record PagedVolume::Pager::band0_record_inside(const Coord& v, CachedBrick& home, int64_t index, uint32_t m) {
  const Band0Template& t = template_of(v);
  const Near near = near_of(v);
  float f[11];
  DiamondBounds range = polyhedron_values(v, t, home, near, f);
  // As read_polyhedron with every polyhedron vertex real and in the box.
  DiamondValues dv;
  dv.type = t.type;
  dv.fa = f[0], dv.fb = f[1], dv.fv = f[2];
  std::copy(f + 3, f + t.values, dv.ring);
  const RecordFields held = fields_held(home);
  Saturation sat;
  for (int i = 0; i < t.children; ++i) {
    const Slot c = slot_near(v, t.child[static_cast<size_t>(i)], index, near);
    sat.add(child_record(c.index, c.m, true, held), range, true);
  }
  CriticalCounts unused = {{0, 0, 0}, {0, 0, 0}};
  const Record r = finish_record(dv, t.shape, true, range, sat, unused, true, nullptr, held.weights);
  store_band0_record(home, m, r, true, held);
  return r;
}

void PagedVolume::Pager::band0_bounds_inside(const Coord& v, CachedBrick& home, int64_t index, uint32_t m) {
  const Band0Template& t = template_of(v);
  const Near near = near_of(v);
  if (home.narrow() && home.surplus() == nullptr) return band0_narrow_inside(v, t, index, home, m, near);
  float f[11];
  // As read_polyhedron and finish_record (the record builder's) with every vertex in the box.
  DiamondBounds range = polyhedron_values(v, t, home, near, f);
  const bool surplus = home.surplus() != nullptr;
  Saturation sat;
  for (int i = 0; i < t.children; ++i) {
    const Slot s = slot_near(v, t.child[static_cast<size_t>(i)], index, near);
    uint64_t word;
    if (!s.home) {
      word = bounds_word(s.index, s.m);
    } else if ((word = word_of(home, s.m)) == kUnsetBounds) {
      compute_band0(home, index, s.m, false);  // HOME is held: no lookup, no hold
      word = word_of(home, s.m);
    }
    const PackedBounds p = bounds_of(word);
    Record c;
    c.bounds = {bf16_to_float(p.lo), bf16_to_float(p.hi), p.bound,
                surplus ? bf16_to_float(this->surplus(s.index, s.m)) : 0.0f};
    sat.add(c, range, false);
  }
  const double eta = std::fabs(static_cast<double>(f[2]) - 0.5 * (static_cast<double>(f[0]) + f[1]));
  range.error_bound = round_up(eta + sat.bound);
  range.error_surplus = std::max(round_up(eta), sat.surplus);
  if (surplus) store(home.surplus() + m, bf16_up(range.error_surplus));
  store_bounds(home, m, pack_bounds(range));
}

void PagedVolume::Pager::band0_narrow_inside(const Coord& v, const Band0Template& t, int64_t index, CachedBrick& home,
                                             uint32_t m, const Near& near) {
  // band0_bounds_inside's record in the narrow word's own integers (narrow_word_of): the
  // values and the range are bytes, a bound a count of halves, and min, max, |2 c - a - b| and a
  // sum of halves are exact there as they are in floats. The same word, bit for bit, for a
  // fraction of the work: a fine extraction from a one-byte store computes millions.
  const auto* values = static_cast<const uint8_t*>(home.values().data());
  uint32_t lo = 255, hi = 0, g[3] = {0, 0, 0};
  for (int i = 0; i < t.values; ++i) {
    const auto& o = t.value[static_cast<size_t>(i)];
    const auto x = near.in_brick(o) ? uint32_t{values[near.index(o)]}
                                    : static_cast<uint32_t>(value_at({v[0] + o[0], v[1] + o[1], v[2] + o[2]}));
    if (i < 3) g[i] = x;
    lo = std::min(lo, x), hi = std::max(hi, x);
  }
  uint32_t* words = home.narrow_bounds();
  uint32_t halves = 0;  // the children's largest bound
  for (int i = 0; i < t.children; ++i) {
    const Slot s = slot_near(v, t.child[static_cast<size_t>(i)], index, near);
    uint32_t w;
    if (!s.home) {
      w = narrow_word(s.index, s.m);
    } else if ((w = load(words + s.m)) == kUnsetNarrowBounds) {
      compute_band0(home, index, s.m, false);  // HOME is held: no lookup, no hold
      w = load(words + s.m);
    }
    lo = std::min(lo, w & 0xffu), hi = std::max(hi, w >> 8 & 0xffu), halves = std::max(halves, w >> 16);
  }
  const auto eta = static_cast<uint32_t>(
      std::abs(2 * static_cast<int32_t>(g[2]) - static_cast<int32_t>(g[0]) - static_cast<int32_t>(g[1])));
  uint32_t bound = 0xffffu;  // +inf stays +inf
  if (halves != 0xffffu) {
    bound = halves + eta;
    if (bound > 0xfffeu) throw std::logic_error("a band-0 record of one-byte values is not narrow");
  }
  store(words + m, lo | hi << 8 | bound << 16);
}

void PagedVolume::Pager::store_bounds(CachedBrick& home, uint32_t m, const PackedBounds& p) {
  const uint64_t word = isotope::bounds_word(p);
  if (!home.narrow()) return store(home.bounds() + m, word);
  // Computed from values the cache checked to be integers of 0..255: always narrow.
  uint32_t bad = 0;
  const uint32_t narrow = narrow_word_of(static_cast<uint32_t>(word), static_cast<uint32_t>(word >> 32), bad);
  if (bad != 0) throw std::logic_error("a band-0 record of one-byte values is not narrow");
  store(home.narrow_bounds() + m, narrow);
}

void PagedVolume::Pager::compute_band0(CachedBrick& home, int64_t index, uint32_t m, bool topology) {
  const Coord v = band0_node(home, m);
  if (!inside_by_one(v))
    band0_record(v, topology);
  else if (topology)
    band0_record_inside(v, home, index, m);
  else
    band0_bounds_inside(v, home, index, m);
}

uint64_t PagedVolume::Pager::computed_bounds_word(int64_t index, uint32_t m) {
  // Held until the record is read back: computing it reads other bricks, which may take this one's
  // pin, and the cache may then evict it, and a brick decoded again has band 0's records unset
  // (the record just computed would read as none). Held, a lookup gets this very brick back.
  const std::shared_ptr<CachedBrick> home = hold(index);
  compute_band0(*home, index, m, false);
  return word_of(*home, m);
}

uint32_t PagedVolume::Pager::narrow_word(int64_t index, uint32_t m) {
  const uint32_t w = load(brick(index).narrow_bounds() + m);
  if (w != kUnsetNarrowBounds) return w;
  const std::shared_ptr<CachedBrick> home = hold(index);  // as in computed_bounds_word
  compute_band0(*home, index, m, false);
  return load(home->narrow_bounds() + m);
}

Bf16 PagedVolume::Pager::surplus(int64_t index, uint32_t m) {
  CachedBrick& b = brick(index);
  if (!b.surplus()) volume_->cache_.require(b, index, {false, false, false, true});
  const Bf16 s = load(b.surplus() + m);
  if (s != kUnsetSurplus || b.band() != 0) return s;
  const std::shared_ptr<CachedBrick> home = hold(index);  // as in computed_bounds_word
  compute_band0(*home, index, m, false);
  return load(home->surplus() + m);
}

DiamondTopology PagedVolume::Pager::topology(int64_t index, uint32_t m, const RecordFields& read) {
  CachedBrick* b = &brick(index);
  if (!b->has(read)) volume_->cache_.require(*b, index, read);
  constexpr uint32_t kNever = 0x3f80u;  // [1, 0): empty
  auto words = [&] {
    return std::array<uint64_t, 3>{read.exact ? load(b->exact() + m) : kNever,
                                   read.paper ? load(b->paper() + m) : kNever,
                                   read.weights ? load(b->weights() + m) : 0};
  };
  std::array<uint64_t, 3> w = words();
  if (b->band() == 0 && ((read.exact && w[0] == kUnsetInterval) || (read.paper && w[1] == kUnsetInterval) ||
                         (read.weights && w[2] == kUnsetWeights))) {
    const std::shared_ptr<CachedBrick> home = hold(index);  // as in computed_bounds_word
    compute_band0(*home, index, m, true);
    b = home.get();
    w = words();
  }
  return topology_of(static_cast<uint32_t>(w[0]), static_cast<uint32_t>(w[1]), w[2]);
}

Mesh extract(const PagedVolume& volume, const ExtractCall& options, ExtractStats* stats, BudgetMemo* memo) {
  return extract_adaptive(volume, options, stats, std::nullopt, memo);
}

Hierarchy load_hierarchy(const PagedVolume& volume, const RecordFields& fields) {
  const StoreLayout& layout = volume.layout();
  const StoreHeader& h = volume.cache().store().header();
  Hierarchy out = Hierarchy::allocate(layout.dims(), layout.brick_bits(), fields);
  out.set_geometry(h.origin, h.spacing);
  out.set_value_map(h.value_offset, h.value_scale);
  PreprocessStats stats;
  for (int t = 0; t < 3; ++t)
    stats.critical_paper[t] = h.critical_paper[t], stats.critical_exact[t] = h.critical_exact[t];
  out.set_stats(stats);
  const auto nodes = static_cast<uint32_t>(layout.brick_nodes());
  parallel_for(int64_t{0}, layout.brick_count(), [&](int64_t index) {
    PagedVolume::Reader reader = volume.reader();
    PagedVolume::Pager& pager = reader.bricks();
    pager.values(index).visit([&](const auto* values) { std::copy(values, values + nodes, out.values(index)); });
    const BrickView to = out.brick(index);
    const int band = pager.band(index);
    const auto [j, b] = volume.cache().store().locate_brick(index);
    const Band& grid = layout.band(j);
    const int64_t t = layout.brick_width();
    const Record absent{DiamondBounds{0, 0, 0, 0}, DiamondTopology{0, 0, 0, 0, {0, 0, 0}}};
    for (uint32_t m = 0; m < nodes; ++m) {
      const Box3 g{b[0] * t + compact_bits_3(m), b[1] * t + compact_bits_3(m >> 1), b[2] * t + compact_bits_3(m >> 2)};
      const bool in_grid = g[0] < grid.nodes[0] && g[1] < grid.nodes[1] && g[2] < grid.nodes[2];
      if ((m & 7) == 0 || !in_grid || band == layout.lattice().k) {
        store_record(to, m, absent);
        continue;
      }
      to.bounds[m] = pager.bounds_word(index, m);
      if (fields.surplus) to.surplus[m] = pager.surplus(index, m);
      if (!fields.topology()) continue;
      const PackedTopology p = pack_topology(pager.topology(index, m, fields), 0);
      if (to.exact) to.exact[m] = interval_word(p.exact_lo, p.exact_hi);
      if (to.paper) to.paper[m] = interval_word(p.paper_lo, p.paper_hi);
      if (to.weights) to.weights[m] = weights_word(p.weight);
    }
  });
  return out;
}

}  // namespace isotope
