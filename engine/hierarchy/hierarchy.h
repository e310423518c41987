#pragma once
// The hierarchy as extraction reads it: the bands and bricks of the StoreLayout, each brick
// holding its nodes' values and the compact records (docs/FORMAT.md, "Compact records") of its scale-j
// nodes, in Morton order within the brick, so that a subtree of the traversal reads a few
// contiguous kilobytes. The same bricks, byte for byte, whether built in memory from a volume (this
// file: a one-shot extraction with eps > 0) or read from a store (PagedVolume), so a
// store's extraction equals the in-memory one and a warm brick cache runs as fast as memory.
//
// Fields a mode does not read need not be held (RecordFields, fields_for).
#include <algorithm>
#include <array>
#include <atomic>
#include <bit>
#include <cstdint>
#include <memory>
#include <stdexcept>
#include <type_traits>

#include "engine/core/progress_reporter.h"
#include "engine/hierarchy/compact_record.h"
#include "engine/hierarchy/lattice.h"
#include "engine/hierarchy/multires_volume.h"
#include "engine/hierarchy/record.h"
#include "engine/hierarchy/record_fields.h"
#include "engine/hierarchy/store_layout.h"
#include "isotope/volume.h"

namespace isotope {

// One brick's arrays, indexed by the Morton code of a node within the brick (brick_morton);
// entries of nodes coarser than the band (code a multiple of 8) hold nothing. A null array is a
// field not held. Written through std::atomic_ref where a store fills band 0's records on first
// use (PagedVolume).
struct BrickView {
  const float* values = nullptr;
  uint64_t* bounds = nullptr;   // bounds_word(PackedBounds)
  uint16_t* surplus = nullptr;  // bfloat16
  uint32_t* exact = nullptr;    // exact_lo | exact_hi << 16
  uint32_t* paper = nullptr;    // paper_lo | paper_hi << 16
  uint64_t* weights = nullptr;  // weight 0 | 1 << 16 | 2 << 32
};

inline uint32_t interval_word(Bf16 lo, Bf16 hi) { return uint32_t{lo} | uint32_t{hi} << 16; }
inline uint64_t weights_word(const Bf16 (&w)[3]) {
  return uint64_t{w[0]} | uint64_t{w[1]} << 16 | uint64_t{w[2]} << 32;
}

// The topology of a node from the words held (fields not held read as "never critical").
inline DiamondTopology topology_of(uint32_t exact, uint32_t paper, uint64_t weights) {
  PackedTopology p;
  p.exact_lo = static_cast<Bf16>(exact), p.exact_hi = static_cast<Bf16>(exact >> 16);
  p.paper_lo = static_cast<Bf16>(paper), p.paper_hi = static_cast<Bf16>(paper >> 16);
  for (int w = 0; w < 3; ++w) p.weight[w] = static_cast<Bf16>(weights >> (16 * w));
  return unpack(p);
}

// Writes record r (packed here, rounded as round_record rounds it) of Morton code m into a
// brick, the fields the brick holds.
void store_record(const BrickView& brick, uint32_t m, const Record& r);

class BandTile;
// The brick of a built tile whose first node is `origin` (G_j units): values (into `values`) and
// records, every entry written (nodes beyond the band's grid: value 0, an all-zero record).
void fill_brick(const BandTile& tile, const Box3& origin, const BrickView& out, float* values);

// Nodes per brick and the Morton code of a node within its brick, by table.
class BrickIndexer {
 public:
  explicit BrickIndexer(const StoreLayout& layout);
  int64_t brick_nodes() const { return nodes_; }
  // Brick index (directory order) and Morton code of node g of band j (G_j units, inside the grid).
  int64_t locate(int j, int64_t gx, int64_t gy, int64_t gz, uint32_t* m) const {
    const int bits = bits_;
    *m = kSpreadBits3[static_cast<size_t>(gx & mask_)] | kSpreadBits3[static_cast<size_t>(gy & mask_)] << 1 |
         kSpreadBits3[static_cast<size_t>(gz & mask_)] << 2;
    const BandInfo& b = band_[static_cast<size_t>(j)];
    return b.first_brick + ((gz >> bits) * b.bricks_y + (gy >> bits)) * b.bricks_x + (gx >> bits);
  }
  // Whether node g of band j lies in the band's grid.
  bool in_grid(int j, int64_t gx, int64_t gy, int64_t gz) const {
    const BandInfo& b = band_[static_cast<size_t>(j)];
    return gx < b.nodes[0] && gy < b.nodes[1] && gz < b.nodes[2];
  }

 private:
  struct BandInfo {
    int64_t first_brick = 0, bricks_x = 0, bricks_y = 0;
    std::array<int64_t, 3> nodes{};
  };
  int bits_ = 0;
  int64_t mask_ = 0, nodes_ = 0;
  std::array<BandInfo, 24> band_{};
};

// The hierarchy built in memory, every brick present.
class Hierarchy {
 public:
  // The banded build (build_bands) on all threads, with only the topology fields asked
  // for, in bricks of 2^brick_bits nodes a side (kMemoryBrickBits: StoreLayout::memory_brick_bits).
  // Throws InvalidInput for dimensions below 2 or non-finite values.
  static constexpr int kMemoryBrickBits = 0;
  static Hierarchy build(const Volume& volume, const RecordFields& fields = {}, int brick_bits = kMemoryBrickBits,
                         const ProgressCallback& progress = {});
  // Empty bricks to be filled (a store read whole by a StoreReader).
  static Hierarchy allocate(const std::array<int64_t, 3>& dims, int brick_bits, const RecordFields& fields);

  Hierarchy(Hierarchy&&) = default;
  Hierarchy& operator=(Hierarchy&&) = default;

  const StoreLayout& layout() const { return *layout_; }
  const Lattice& lattice() const { return layout_->lattice(); }
  const std::array<int64_t, 3>& data_dims() const { return layout_->dims(); }
  const std::array<double, 3>& origin() const { return origin_; }
  const std::array<double, 3>& spacing() const { return spacing_; }
  double value_offset() const { return value_offset_; }
  double value_scale() const { return value_scale_; }
  double error_fold() const { return 0; }  // values held exactly
  const RecordFields& fields() const { return fields_; }
  const PreprocessStats& stats() const { return stats_; }
  void set_geometry(const std::array<double, 3>& origin, const std::array<double, 3>& spacing) {
    origin_ = origin, spacing_ = spacing;
  }
  void set_value_map(double offset, double scale) { value_offset_ = offset, value_scale_ = scale; }
  void set_stats(const PreprocessStats& s) { stats_ = s; }
  int64_t memory_bytes() const;
  // What build() would take for a volume of these dimensions, before it allocates anything: the
  // memory_bytes() of the hierarchy it returns.
  static int64_t memory_bytes(const std::array<int64_t, 3>& dims, const RecordFields& fields = {},
                              int brick_bits = kMemoryBrickBits);

  BrickView brick(int64_t index) const {
    const auto at = static_cast<size_t>(index * indexer_->brick_nodes());
    return {values_.get() + at,
            bounds_.get() + at,
            surplus_ ? surplus_.get() + at : nullptr,
            exact_ ? exact_.get() + at : nullptr,
            paper_ ? paper_.get() + at : nullptr,
            weights_ ? weights_.get() + at : nullptr};
  }
  float* values(int64_t index) { return values_.get() + index * indexer_->brick_nodes(); }
  const float* values_data() const { return values_.get(); }
  const uint64_t* bounds_data() const { return bounds_.get(); }
  const uint16_t* surplus_data() const { return surplus_.get(); }
  const uint32_t* exact_data() const { return exact_.get(); }
  const uint32_t* paper_data() const { return paper_.get(); }
  const uint64_t* weights_data() const { return weights_.get(); }
  const BrickIndexer& indexer() const { return *indexer_; }

  // As a traversal source (TraversalSource).
  class Reader;
  Reader reader() const;

 private:
  Hierarchy() = default;
  std::unique_ptr<StoreLayout> layout_;  // by pointer: readers keep references across moves
  std::unique_ptr<BrickIndexer> indexer_;
  std::array<double, 3> origin_{0, 0, 0}, spacing_{1, 1, 1};
  double value_offset_ = 0, value_scale_ = 1;
  RecordFields fields_;
  PreprocessStats stats_;
  std::unique_ptr<float[]> values_;
  std::unique_ptr<uint64_t[]> bounds_;
  std::unique_ptr<uint16_t[]> surplus_;
  std::unique_ptr<uint32_t[]> exact_, paper_;
  std::unique_ptr<uint64_t[]> weights_;
};

// f(p) over a brick's values: p is the array itself where they are floats (a hierarchy in
// memory), or what a paged brick holds them in (BrickValues::visit).
template <class Values, class F>
decltype(auto) with_values(const Values& values, F&& f) {
  if constexpr (std::is_pointer_v<Values>)
    return f(values);
  else
    return values.visit(f);
}

// Values and records by coordinates over any set of bricks, as a traversal reader
// (RecordReader). `Bricks` gives a brick's arrays (view) and reads records: a
// record's range and bound (range_bound: its word's, as floats, error_surplus 0), its words
// (bounds_word, topology). Lookups as MultiresVolume's: a node's value is read from band j (its
// coordinates lie on G_j), clamped into the data box beyond band j's grid; a record from the band
// of the node's scale.
template <class Bricks>
class CompactLookup {
 public:
  struct Handle {
    int64_t index = 0;  // brick
    uint32_t m = 0;     // Morton code within it
  };

  CompactLookup(const StoreLayout& layout, const BrickIndexer& indexer, Bricks bricks)
      : layout_(layout), indexer_(indexer), bricks_(std::move(bricks)) {}

  float value(const Coord& c, int j) {
    Coord q = c;
    if (!indexer_.in_grid(j, c[0] >> j, c[1] >> j, c[2] >> j)) [[unlikely]] {
      for (int a = 0; a < 3; ++a) q[a] = std::min(c[a], layout_.dims()[a] - 1);
      j = scale_of(q, layout_.lattice());
    }
    uint32_t m = 0;
    const int64_t index = indexer_.locate(j, q[0] >> j, q[1] >> j, q[2] >> j, &m);
    return bricks_.values(index)[m];
  }
  Handle locate(uint64_t packed) const {
    constexpr uint64_t kMask = (uint64_t{1} << 21) - 1;
    const int64_t x = static_cast<int64_t>(packed & kMask), y = static_cast<int64_t>((packed >> 21) & kMask),
                  z = static_cast<int64_t>(packed >> 42);
    const int j = std::min(layout_.lattice().k, std::countr_zero(static_cast<uint64_t>(x | y | z)));
    Handle h;
    h.index = indexer_.locate(j, x >> j, y >> j, z >> j, &h.m);
    return h;
  }
  DiamondBounds bounds(const Handle& h, const RecordFields& read) {
    DiamondBounds b = bricks_.range_bound(h.index, h.m);
    if (read.surplus) b.error_surplus = bf16_to_float(bricks_.surplus(h.index, h.m));
    return b;
  }
  DiamondTopology topology(const Handle& h, const RecordFields& read) { return bricks_.topology(h.index, h.m, read); }
  void prefetch(const Handle& h) { bricks_.prefetch(h.index, h.m); }
  // The value of the node whose record h locates (h from locate() of a vertex within the data
  // box's records, as every vertex the traversal refines is), read in the node's own band: the data
  // value at the node clamped into the box, which every band holding the node has there and which
  // value() gives beyond a band's grid (docs/FORMAT.md, "Verification").
  float value_at_record(const Handle& h) { return bricks_.values(h.index)[h.m]; }

  // The values of band-0 nodes lo .. lo + n (inclusive; inside band 0's grid) into f, x fastest,
  // rows `stride` apart: a block of finest cells (extract_finest), from every brick it spans.
  bool block_values(const Coord& lo, const std::array<int64_t, 3>& n, float* f, int64_t stride) {
    const int bits = layout_.brick_bits();
    const int64_t t = layout_.brick_width();
    for_each_brick_of(lo, n, [&](int64_t bx, int64_t by, int64_t bz) {
      uint32_t unused = 0;
      const int64_t x0 = std::max(lo[0], bx * t), x1 = std::min(lo[0] + n[0], bx * t + t - 1);
      const int64_t y0 = std::max(lo[1], by * t), y1 = std::min(lo[1] + n[1], by * t + t - 1);
      const int64_t z0 = std::max(lo[2], bz * t), z1 = std::min(lo[2] + n[2], bz * t + t - 1);
      with_values(bricks_.values(indexer_.locate(0, bx << bits, by << bits, bz << bits, &unused)),
                  [&](const auto* values) {
                    for (int64_t z = z0; z <= z1; ++z)
                      for (int64_t y = y0; y <= y1; ++y) {
                        float* row = f + ((z - lo[2]) * stride + (y - lo[1])) * stride - lo[0];
                        const uint32_t yz = spread_bits_3(y & (t - 1)) << 1 | spread_bits_3(z & (t - 1)) << 2;
                        for (int64_t x = x0; x <= x1; ++x) row[x] = values[yz | spread_bits_3(x & (t - 1))];
                      }
                  });
    });
    return true;
  }
  // For a source that reads its bricks on demand (a store): whether hints pay now (the source is
  // read from the disk, not all from memory), and a hint that block_values(lo, n, ...) will be
  // asked for soon, so that the reads of the bricks it spans run while other blocks are marched.
  bool hints_pay() const requires requires(const Bricks& b) { b.hints_pay(); }
  { return bricks_.hints_pay(); }
  void prefetch_block(const Coord& lo, const std::array<int64_t, 3>& n) requires requires(Bricks& b) {
    b.prefetch_brick(int64_t{});
  }
  {
    const int bits = layout_.brick_bits();
    for_each_brick_of(lo, n, [&](int64_t bx, int64_t by, int64_t bz) {
      uint32_t unused = 0;
      bricks_.prefetch_brick(indexer_.locate(0, bx << bits, by << bits, bz << bits, &unused));
    });
  }
  Bricks& bricks() { return bricks_; }

 private:
  // f(bx, by, bz) for each band-0 brick (brick coordinates) that nodes lo .. lo + n span.
  template <class F>
  void for_each_brick_of(const Coord& lo, const std::array<int64_t, 3>& n, F f) const {
    const int bits = layout_.brick_bits();
    for (int64_t bz = lo[2] >> bits; bz <= (lo[2] + n[2]) >> bits; ++bz)
      for (int64_t by = lo[1] >> bits; by <= (lo[1] + n[1]) >> bits; ++by)
        for (int64_t bx = lo[0] >> bits; bx <= (lo[0] + n[0]) >> bits; ++bx) f(bx, by, bz);
  }
  const StoreLayout& layout_;
  const BrickIndexer& indexer_;
  Bricks bricks_;
};

namespace hierarchy_internal {
// Every brick of an in-memory hierarchy, all records present.
struct MemoryBricks {
  const Hierarchy* h;
  int64_t brick_nodes;
  const float* values(int64_t index) const { return h->values_data() + index * brick_nodes; }
  uint64_t bounds_word(int64_t index, uint32_t m) const { return h->bounds_data()[index * brick_nodes + m]; }
  DiamondBounds range_bound(int64_t index, uint32_t m) const { return isotope::range_bound(bounds_word(index, m)); }
  Bf16 surplus(int64_t index, uint32_t m) const { return h->surplus_data()[index * brick_nodes + m]; }
  DiamondTopology topology(int64_t index, uint32_t m, const RecordFields& read) const {
    const int64_t at = index * brick_nodes + m;
    constexpr uint32_t kNever = 0x3f80u;  // [1, 0): empty
    return topology_of(read.exact ? h->exact_data()[at] : kNever, read.paper ? h->paper_data()[at] : kNever,
                       read.weights ? h->weights_data()[at] : 0);
  }
  void prefetch(int64_t index, uint32_t m) const { __builtin_prefetch(h->bounds_data() + index * brick_nodes + m); }
};
}  // namespace hierarchy_internal

class Hierarchy::Reader : public CompactLookup<hierarchy_internal::MemoryBricks> {
 public:
  explicit Reader(const Hierarchy& h) : CompactLookup(h.layout(), h.indexer(), {&h, h.layout().brick_nodes()}) {}
};
inline Hierarchy::Reader Hierarchy::reader() const { return Reader(*this); }

}  // namespace isotope
