#include "engine/hierarchy/band_tile.h"

#include <algorithm>
#include <atomic>
#include <bit>
#include <cassert>
#include <cmath>
#include <cstddef>
#include <memory>
#include <stdexcept>
#include <string>
#include <tuple>
#include <type_traits>

#include "engine/core/lanes.h"
#include "isotope/error.h"

namespace isotope {

std::pair<Box3, Box3> BandTile::window_of(const StoreLayout& layout, int band, const Box3& core_lo,
                                          const Box3& core_hi) {
  // A node's record reads nodes two steps away along the axes where it is odd (face and cube
  // centres), one step along the others (computable(), below): an even first node of the core
  // (the start of a brick) needs one node below it, an odd one two; two above its last.
  const int64_t top = layout.lattice().n >> band;
  Box3 lo, hi;
  for (int a = 0; a < 3; ++a) {
    lo[a] = std::max<int64_t>(0, core_lo[a] - ((core_lo[a] & 1) ? 2 : 1));
    hi[a] = std::min(top, core_hi[a] - 1 + 2);
  }
  return {lo, hi};
}

std::pair<Box3, Box3> BandTile::next_of(const StoreLayout& layout, int band, const Box3& core_lo, const Box3& core_hi) {
  Box3 lo, hi;
  for (int a = 0; a < 3; ++a) {
    lo[a] = core_lo[a] / 2;
    hi[a] = core_hi[a] / 2;
    if (band == layout.lattice().k)
      hi[a] = lo[a];  // no band above the corners
    else if (core_hi[a] == layout.band(band).nodes[a])
      hi[a] = layout.band(band + 1).nodes[a];
  }
  return {lo, hi};
}

BandTile::BandTile(const StoreLayout& layout, int band, const Box3& core_lo, const Box3& core_hi, Buffers buffers)
    : layout_(layout),
      j_(band),
      core_lo_(core_lo),
      core_hi_(core_hi),
      count_lo_(core_lo),
      count_hi_(core_hi),
      values_(std::move(buffers.values)),
      records_(std::move(buffers.records)),
      children_(std::move(buffers.children)) {
  top_ = layout.lattice().n >> band;
  std::tie(lo_, hi_) = window_of(layout, band, core_lo, core_hi);
  for (int a = 0; a < 3; ++a) {
    size_[a] = hi_[a] - lo_[a] + 1;
    cells_[a] = std::max<int64_t>(1, size_[a] - 1);
  }
  std::tie(next_lo_, next_hi_) = next_of(layout, band, core_lo, core_hi);
  // Grown, never cleared: every entry read is written first (values by the caller, records by
  // build() before any parent reads them, children by the caller where they exist), and
  // re-initializing the arrays of a large tile costs as much as filling them.
  const auto nodes = static_cast<size_t>(size_[0] * size_[1] * size_[2]);
  if (values_.size() < nodes) detail::resize_prefaulted(values_, nodes);
  if (records_.size() < nodes) detail::resize_prefaulted(records_, nodes);
  const auto cells = static_cast<size_t>(cells_[0] * cells_[1] * cells_[2]);
  if (band > 0 && children_.size() < cells) detail::resize_prefaulted(children_, cells);
}

float BandTile::value(const Coord& c) const {
  const Box3 g{c[0] >> j_, c[1] >> j_, c[2] >> j_};
  assert(g[0] >= lo_[0] && g[0] <= hi_[0] && g[1] >= lo_[1] && g[1] <= hi_[1] && g[2] >= lo_[2] && g[2] <= hi_[2]);
  return node_value(g);
}

bool BandTile::child(const Coord& u, Record& r) const {
  const Lattice& l = layout_.lattice();
  const int s = scale_of(u, l);
  for (int a = 0; a < 3; ++a)
    if (u[a] > record_extent(l, layout_.dims(), a, s)) return false;
  if (s == j_) {
    r = node_record({u[0] >> j_, u[1] >> j_, u[2] >> j_});
  } else {
    assert(s == j_ - 1 && "a scale-j vertex's children are of scale j or j-1 cube centres");
    r = child_record({u[0] >> j_, u[1] >> j_, u[2] >> j_});
  }
  return true;
}

Record BandTile::next_child(const Box3& g) const {
  const Band& band = layout_.band(j_);
  const Box3 c{2 * g[0] + 1, 2 * g[1] + 1, 2 * g[2] + 1};
  for (int a = 0; a < 3; ++a)
    if (c[a] >= band.nodes[a]) return Record{};
  return node_record(c);
}

void BandTile::next_row(int64_t x0, int64_t x1, int64_t y, int64_t z, float* values, Record* children,
                        int64_t child_count) const {
  if (x1 <= x0) return;
  const float* from = &node_value({2 * x0, 2 * y, 2 * z});
  for (int64_t i = 0; i < x1 - x0; ++i) values[i] = from[2 * i];
  const int64_t n = child_count < 0 ? x1 - x0 : child_count;
  // The cube centres 2g + 1 in band j's grid: g < nodes / 2 along x.
  const Box3& nodes = layout_.band(j_).nodes;
  const int64_t inside =
      2 * y + 1 >= nodes[1] || 2 * z + 1 >= nodes[2] ? 0 : std::clamp<int64_t>(nodes[0] / 2 - x0, 0, n);
  if (inside > 0) {
    const Record* centre = &node_record({2 * x0 + 1, 2 * y + 1, 2 * z + 1});
    for (int64_t i = 0; i < inside; ++i) children[i] = centre[2 * i];
  }
  std::fill(children + inside, children + n, Record{});
}

void BandTile::store(const Coord& v, const Record& r) {
  records_[static_cast<size_t>(index({v[0] >> j_, v[1] >> j_, v[2] >> j_}, size_))] = r;
}

// Whether every node g's record depends on lies in the window (or beyond a lattice face, where
// the diamond is cut): one step for edge midpoints; for face and cube centres two steps along
// their odd axes (children one step away, and those children's own reach), one along the even.
bool BandTile::computable(const Box3& g, int odd) const {
  for (int a = 0; a < 3; ++a) {
    const int64_t m = (odd >= 2 && (g[a] & 1)) ? 2 : 1;
    if (g[a] - m < lo_[a] && lo_[a] != 0) return false;
    if (g[a] + m > hi_[a] && hi_[a] != top_) return false;
  }
  return true;
}

bool BandTile::inside_data_box(const Box3& g) const {
  const int64_t h = int64_t{1} << j_;
  for (int a = 0; a < 3; ++a)
    if ((g[a] << j_) - h < 0 || (g[a] << j_) + h > layout_.dims()[a] - 1) return false;
  return true;
}

BandTile::DiamondTemplate* BandTile::shared_templates(int k, int j, const Box3& size, const Box3& cells) {
  struct Set {
    int k = -1, j = -1;
    Box3 size{}, cells{};
    DiamondTemplate templates[64];
  };
  // Eight, in turn: a fused pass's tiles of bands j and j + 1 take turns on a thread, and the
  // tiles at the grid's far faces are thinner (one window size for each face, edge and corner).
  // On the heap: 15 KB each.
  constexpr size_t kSets = 8;
  thread_local std::unique_ptr<std::array<Set, kSets>> sets;
  thread_local size_t next = 0;
  if (!sets) sets = std::make_unique<std::array<Set, kSets>>();
  for (Set& set : *sets)
    if (set.k == k && set.j == j && set.size == size && set.cells == cells) return set.templates;
  Set& set = (*sets)[next];
  next = (next + 1) % kSets;
  set.k = k, set.j = j, set.size = size, set.cells = cells;
  std::fill(std::begin(set.templates), std::end(set.templates), DiamondTemplate{});  // none ready
  return set.templates;
}

namespace {

// What SLOT points to, made by MAKE (a unique_ptr) and published there if it points to nothing
// yet: of threads that race, the first to publish wins and the others free what they made.
template <class T, class Make>
T& publish_once(std::atomic<T*>& slot, const Make& make) {
  T* p = slot.load(std::memory_order_acquire);
  if (p) return *p;
  std::unique_ptr<T> made = make();
  if (slot.compare_exchange_strong(p, made.get(), std::memory_order_acq_rel)) p = made.release();
  return *p;
}

}  // namespace

const BandTile::DiamondGeometry& BandTile::geometry_of(const Lattice& l, int j, int parity, const Diamond& d) {
  // Per (k, j), 64 classes, published once each: a thread that finds a class empty makes it from
  // its own vertex of the class (every one gives the same bits) and the first to publish wins.
  // Kept for the process's life: at most 64 x 1.5 KB a band of each lattice size built.
  constexpr int kMaxK = 40;  // a lattice of 2^40 cells a side: far beyond any volume's
  using Classes = std::array<std::atomic<const DiamondGeometry*>, 64>;
  static std::atomic<Classes*> bands[kMaxK + 1][kMaxK + 1];
  if (l.k > kMaxK) throw InvalidInput("lattice of 2^" + std::to_string(l.k) + " cells a side");
  Classes& classes = publish_once(bands[l.k][j], [] { return std::make_unique<Classes>(); });  // null pointers
  return publish_once(classes[static_cast<size_t>(parity)], [&] {
    const DiamondShape shape = shape_of(d, l);
    return std::unique_ptr<const DiamondGeometry>(new DiamondGeometry{shape, gradients_of(shape)});
  });
}

const BandTile::DiamondTemplate& BandTile::template_for(const Box3& g) {
  const int parity = static_cast<int>((g[0] & 3) | (g[1] & 3) << 2 | (g[2] & 3) << 4);
  DiamondTemplate& t = templates_[parity];
  if (t.ready) return t;
  const Lattice& l = layout_.lattice();
  const Diamond d = diamond_of({g[0] << j_, g[1] << j_, g[2] << j_}, l);
  const int64_t base = index(g, size_), cell_base = index(g, cells_);
  auto value_offset = [&](const Coord& p) { return index({p[0] >> j_, p[1] >> j_, p[2] >> j_}, size_) - base; };
  t.type = d.type;
  t.geometry = &geometry_of(l, j_, parity, d);
  t.ring_count = d.ring_count;
  t.a = value_offset(d.a);
  t.b = value_offset(d.b);
  for (int i = 0; i < d.ring_count; ++i) t.ring[i] = value_offset(d.ring[i]);
  for_each_child(d, l, [&](const Coord& u) {
    const Box3 gu{u[0] >> j_, u[1] >> j_, u[2] >> j_};
    if (scale_of(u, l) == j_)
      t.same[t.same_count++] = index(gu, size_) - base;
    else
      t.cube[t.cube_count++] = index(gu, cells_) - cell_base;
  });
  t.ready = true;
  return t;
}

// RecordBuilder::build for a diamond inside the data box, reading through a template; the same
// record bit for bit (the max and hull folds do not depend on the order of the children). Inlined
// in build()'s row loop, its one caller: a call's saving and restoring of registers was a tenth
// of it.
[[gnu::always_inline]] inline void BandTile::build_fast(int64_t base, int64_t cell, const DiamondTemplate& t,
                                                        CriticalCounts& counts, bool topology) {
  const float* v = values_.data() + base;
  DiamondValues dv;
  dv.type = t.type;
  float lo, hi;
  // A ring of the diamond's type, whole inside the box: its size known to the compiler, the
  // loop unrolled.
  auto ring = [&]<int n>(std::integral_constant<int, n>) {
#if defined(__SSE2__)
    if (!signed_zero_) {
      // The values four to a register, min and max taken lane-wise and then across: another
      // order than the scalar folds below, and the same bits, since only -0 and 0 compare equal
      // with other bits, and no value here is -0. Vectors overlap where n is not a multiple of 4
      // (a value taken twice changes neither), each stored where dv holds its values: fa, fb, fv
      // and ring[0] lie in a row (static_assert below).
      const __m128 a = _mm_setr_ps(v[t.a], v[t.b], v[0], v[t.ring[0]]);
      const __m128 b = _mm_setr_ps(v[t.ring[0]], v[t.ring[1]], v[t.ring[2]], v[t.ring[3]]);
      _mm_storeu_ps(&dv.fa, a);
      _mm_storeu_ps(&dv.ring[0], b);
      __m128 l = _mm_min_ps(a, b), h = _mm_max_ps(a, b);
      if constexpr (n > 4) {
        constexpr int first = n - 4;
        const __m128 c =
            _mm_setr_ps(v[t.ring[first]], v[t.ring[first + 1]], v[t.ring[first + 2]], v[t.ring[first + 3]]);
        _mm_storeu_ps(&dv.ring[first], c);
        l = _mm_min_ps(l, c);
        h = _mm_max_ps(h, c);
      }
      lo = least_lane(l);
      hi = greatest_lane(h);
      return;
    }
#endif
    // The order of RecordBuilder's read_polyhedron: of -0 and 0, the first met.
    dv.fa = v[t.a];
    dv.fb = v[t.b];
    dv.fv = v[0];
    lo = std::min({dv.fa, dv.fb, dv.fv});
    hi = std::max({dv.fa, dv.fb, dv.fv});
    for (int i = 0; i < n; ++i) {
      dv.ring[i] = v[t.ring[i]];
      lo = std::min(lo, dv.ring[i]);
      hi = std::max(hi, dv.ring[i]);
    }
  };
  static_assert(offsetof(DiamondValues, fb) == offsetof(DiamondValues, fa) + sizeof(float) &&
                offsetof(DiamondValues, fv) == offsetof(DiamondValues, fa) + 2 * sizeof(float) &&
                offsetof(DiamondValues, ring) == offsetof(DiamondValues, fa) + 3 * sizeof(float));
  static_assert(ring_size(PolyhedronType::octahedron) == 4 && ring_size(PolyhedronType::cube) == 6 &&
                ring_size(PolyhedronType::diamond) == 8);
  switch (t.ring_count) {
    case 4: ring(std::integral_constant<int, 4>{}); break;
    case 6: ring(std::integral_constant<int, 6>{}); break;
    default: assert(t.ring_count == 8); ring(std::integral_constant<int, 8>{});
  }
  DiamondBounds range;
  range.lo = lo;
  range.hi = hi;
  ChildFold fold(range);
  const Record* same = records_.data() + base;
  const Record* cubes = children_.data();  // empty in band 0, whose vertices have no such children
  for (int i = 0; i < t.same_count; ++i) fold.add(same[t.same[i]], topology);
  for (int i = 0; i < t.cube_count; ++i) fold.add(cubes[cell + t.cube[i]], topology);
#if defined(__SSE2__)
  // Most vertices: no critical interval of their own.
  if (!topology || !beyond_both_ends(dv)) {
    fold.store_without_own_topology(dv, records_[static_cast<size_t>(base)]);
    return;
  }
#endif
  const Saturation sat = fold.finish(range);
  records_[static_cast<size_t>(base)] =
      finish_record(dv, t.geometry->shape, true, range, sat, counts, topology, &t.geometry->gradients, weights_);
}

void BandTile::find_constant_blocks() {
  for (int a = 0; a < 3; ++a) blocks_[a] = (size_[a] + 3) / 4;
  const auto count = static_cast<size_t>(blocks_[0] * blocks_[1] * blocks_[2]);
  std::vector<float> lo(count, INFINITY), hi(count, -INFINITY);
  auto block = [&](int64_t bx, int64_t by, int64_t bz) {
    return static_cast<size_t>((bz * blocks_[1] + by) * blocks_[0] + bx);
  };
  // A row's blocks four values at a time. Only equality with one value is asked of the range
  // (below), so the order of the folds does not matter.
  for (int64_t z = 0; z < size_[2]; ++z)
    for (int64_t y = 0; y < size_[1]; ++y) {
      const float* row = values_.data() + (z * size_[1] + y) * size_[0];
      float* const row_lo = lo.data() + block(0, y >> 2, z >> 2);
      float* const row_hi = hi.data() + block(0, y >> 2, z >> 2);
      int64_t x = 0;
      for (; x + 4 <= size_[0]; x += 4) {
        const float l = std::min(std::min(row[x], row[x + 1]), std::min(row[x + 2], row[x + 3]));
        const float h = std::max(std::max(row[x], row[x + 1]), std::max(row[x + 2], row[x + 3]));
        row_lo[x >> 2] = std::min(row_lo[x >> 2], l);
        row_hi[x >> 2] = std::max(row_hi[x >> 2], h);
      }
      for (; x < size_[0]; ++x) {
        row_lo[x >> 2] = std::min(row_lo[x >> 2], row[x]);
        row_hi[x >> 2] = std::max(row_hi[x >> 2], row[x]);
      }
    }
  constant_.assign(count, 0);
  for (int64_t bz = 1; bz + 1 < blocks_[2]; ++bz)
    for (int64_t by = 1; by + 1 < blocks_[1]; ++by)
      for (int64_t bx = 1; bx + 1 < blocks_[0]; ++bx) {
        const float c = lo[block(bx, by, bz)];
        bool same = true;
        for (int64_t dz = -1; dz <= 1 && same; ++dz)
          for (int64_t dy = -1; dy <= 1 && same; ++dy)
            for (int64_t dx = -1; dx <= 1 && same; ++dx) {
              const size_t n = block(bx + dx, by + dy, bz + dz);
              same = lo[n] == c && hi[n] == c;
            }
        constant_[block(bx, by, bz)] = same;
      }
}

void BandTile::build(CriticalCounts& counts, bool topology, bool weights) {
  const Lattice& l = layout_.lattice();
  if (j_ >= l.k) return;  // the corners: no records
  weights_ = weights;
  templates_ = shared_templates(l.k, j_, size_, cells_);
  const Band& band = layout_.band(j_);
  // Band 0 where the values around a node are all one value c: its record is range [c, c], errors
  // 0 (every surplus is 0), no critical interval (the exact rule needs v beyond both a and b; the
  // paper's flags v an extremum, but its interval [c, c) is empty), weights 0; and so are its
  // children's, which lie within one node of it and reach one node further. Only inside the data
  // box's inner part, where no descendant reaches past the box (those are critical in every
  // topology mode: RecordBuilder).
  const bool trivial = j_ == 0;
  if (trivial) find_constant_blocks();
  // Whether a value of the window is -0 (build_fast's vector range takes none).
  uint32_t negative_zeros = 0;
  const int64_t window_nodes = size_[0] * size_[1] * size_[2];
  for (int64_t i = 0; i < window_nodes; ++i)
    negative_zeros |= std::bit_cast<uint32_t>(values_[static_cast<size_t>(i)]) == 0x80000000u;
  signed_zero_ = negative_zeros != 0;
  Box3 trivial_first{}, trivial_last{};
  for (int a = 0; a < 3; ++a) trivial_first[a] = 3, trivial_last[a] = layout_.dims()[a] - 4;
  RecordBuilder<BandTile> builder(*this, j_);
  CriticalCounts halo_counts = {{0, 0, 0}, {0, 0, 0}};  // halo nodes belong to (and are counted by) other tiles
  const int64_t h = int64_t{1} << j_;
  // Finest first, as in MultiresVolume::build: edge midpoints, face centres, cube centres; each
  // class of parities (which coordinates are odd) walked with stride 2. Per axis, the nodes whose
  // records this window can compute (computable()), and those in the core and inside the data
  // box, are ranges: the first fixed once the class is, the others the same for every class.
  struct Class {
    int m = 0;
    Box3 first, last;
  };
  Box3 core_first, core_last, box_first, box_last;
  for (int a = 0; a < 3; ++a) {
    core_first[a] = count_lo_[a], core_last[a] = count_hi_[a] - 1;
    // inside_data_box: (g << j) - h >= 0 and (g << j) + h <= dims - 1
    box_first[a] = (h + (int64_t{1} << j_) - 1) >> j_;
    box_last[a] = (layout_.dims()[a] - 1 - h) >> j_;
  }
  std::vector<Class> classes;
  int64_t z_first = INT64_MAX, z_last = INT64_MIN;
  for (int m = 1; m <= 3; ++m)
    for (int parity = 1; parity < 8; ++parity) {
      const std::array<int64_t, 3> odd{parity & 1, parity >> 1 & 1, parity >> 2 & 1};
      if (odd[0] + odd[1] + odd[2] != m) continue;
      Class k;
      k.m = m;
      bool empty = false;
      for (int a = 0; a < 3; ++a) {
        // Two steps along the odd axes of face and cube centres (their children one step away,
        // and those children's own reach), one step otherwise.
        const int64_t reach = (m >= 2 && odd[a]) ? 2 : 1;
        int64_t lo = lo_[a] == 0 ? 0 : lo_[a] + reach;
        int64_t hi = std::min(hi_[a] == top_ ? hi_[a] : hi_[a] - reach, band.nodes[a] - 1);
        if ((lo & 1) != odd[a]) ++lo;
        k.first[a] = lo;
        k.last[a] = hi;
        empty = empty || lo > hi;
      }
      if (empty) continue;
      classes.push_back(k);
      z_first = std::min(z_first, k.first[2]);
      z_last = std::max(z_last, k.last[2]);
    }
  // One sweep along z, the classes a plane apart: at plane p the edge midpoints of p, the face
  // centres of p - 1 (their children, edge midpoints, lie within one plane: done), the cube
  // centres of p - 2 (their children, face centres, likewise). The same records as a sweep per
  // class, each computed from the same finished children; but the planes a record reads stay in
  // cache, where a whole window (13 MB of records for a tile of 64^3 nodes) does not.
  for (int64_t p = z_first; p <= z_last + 2; ++p)
    for (const Class& k : classes) {
      const int64_t z = p - (k.m - 1);
      if (z < k.first[2] || z > k.last[2] || ((z - k.first[2]) & 1)) continue;
      const Box3 &first = k.first, &last = k.last;
      for (int64_t y = first[1]; y <= last[1]; y += 2) {
        const bool core_yz = y >= core_first[1] && y <= core_last[1] && z >= core_first[2] && z <= core_last[2];
        const bool box_yz = y >= box_first[1] && y <= box_last[1] && z >= box_first[2] && z <= box_last[2];
        const bool trivial_yz =
            trivial && y >= trivial_first[1] && y <= trivial_last[1] && z >= trivial_first[2] && z <= trivial_last[2];
        // Band 0's nodes within a constant block: their record without computing (above).
        const int64_t block_row = (((z - lo_[2]) >> 2) * blocks_[1] + ((y - lo_[1]) >> 2)) * blocks_[0];
        auto set_constant = [this](int64_t at) {
          const float c = values_[static_cast<size_t>(at)];
          Record& r = records_[static_cast<size_t>(at)];
          r = Record{};
          r.bounds = {c, c, 0, 0};
        };
        // The row's nodes whose block may be constant, [block_first, block_last] (none beyond band 0).
        const uint8_t* const row_blocks = trivial_yz ? constant_.data() + block_row : nullptr;
        const int64_t block_first = trivial_yz ? trivial_first[0] : 1, block_last = trivial_yz ? trivial_last[0] : 0;
        auto constant = [&](int64_t x, int64_t at) {
          if (x < block_first || x > block_last || !row_blocks[(x - lo_[0]) >> 2]) return false;
          set_constant(at);
          return true;
        };
        auto counts_of = [&](int64_t x) -> CriticalCounts& {
          return core_yz && x >= core_first[0] && x <= core_last[0] ? counts : halo_counts;
        };
        // x steps by 2. The nodes inside the data box, a range of the row, take templates, of
        // two classes alternately (x mod 4); the few at either end, the general builder.
        auto general = [&](int64_t x) {
          if (!constant(x, index({x, y, z}, size_)))
            builder.build({x << j_, y << j_, z << j_}, counts_of(x), topology, weights);
        };
        int64_t fast_first = last[0] + 2, fast_last = last[0];
        if (box_yz) {
          fast_first = first[0] + std::max<int64_t>(0, box_first[0] - first[0] + 1) / 2 * 2;
          fast_last = std::min(last[0], box_last[0]);
        }
        int64_t x = first[0];
        for (; x <= last[0] && x < fast_first; x += 2) general(x);
        if (x <= fast_last) {
          const DiamondTemplate* templates[2] = {&template_for({x, y, z}), nullptr};
          if (x + 2 <= fast_last) templates[1] = &template_for({x + 2, y, z});
          int64_t at = index({x, y, z}, size_), cell = index({x, y, z}, cells_);
          // The row's core nodes, a range of it, count critical points; the halo's do not.
          const int64_t x0 = x;
          auto run = [&](int64_t end, CriticalCounts& c) {
            // What each node reads, in locals: the run is not inlined, its captures are references,
            // and values the record stores might alias would be loaded again for every node.
            int64_t i = x, i_at = at, i_cell = cell;
            const DiamondTemplate* t = templates[((i - x0) >> 1) & 1];
            const DiamondTemplate* t_next = templates[(((i - x0) >> 1) + 1) & 1];
            const uint8_t* const blocks = row_blocks;
            const int64_t first_block = block_first, last_block = block_last, origin = lo_[0];
            for (; i <= end; i += 2, i_at += 2, i_cell += 2) {
              if (i >= first_block && i <= last_block && blocks[(i - origin) >> 2])
                set_constant(i_at);
              else
                build_fast(i_at, i_cell, *t, c, topology);
              std::swap(t, t_next);
            }
            x = i, at = i_at, cell = i_cell;
          };
          if (core_yz) {
            run(std::min(fast_last, core_first[0] - 1), halo_counts);
            run(std::min(fast_last, core_last[0]), counts);
          }
          run(fast_last, halo_counts);
        }
        for (; x <= last[0]; x += 2) general(x);
      }
    }
}

}  // namespace isotope
