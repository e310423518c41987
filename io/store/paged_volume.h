#pragma once
// A store as a traversal source (TraversalSource): values and records are looked up in the
// bricks that hold them, through a shared BrickCache, so extraction reads only the bricks its
// traversal reaches, and of those only the sections its mode reads. A node's value is read from
// the coarsest band that holds it, and a diamond's record from its own band, so a coarse
// extraction never touches the finer bands. Band 0's records are not stored: each is computed
// from the values the first time the traversal reads it, from the compact records of its
// children (compact records: the same bits as the in-memory build's), and kept in the
// cached brick for the next reader.
#include <array>
#include <atomic>
#include <cstdint>
#include <memory>

#include "engine/extract/extract_drivers.h"
#include "engine/hierarchy/hierarchy.h"
#include "engine/hierarchy/lattice.h"
#include "engine/hierarchy/record_builder.h"
#include "io/store/brick_cache.h"

namespace isotope {

class PagedVolume {
 public:
  explicit PagedVolume(BrickCache& cache);

  const Lattice& lattice() const { return layout_.lattice(); }
  const std::array<int64_t, 3>& data_dims() const { return layout_.dims(); }
  const std::array<double, 3>& origin() const { return header_.origin; }
  const std::array<double, 3>& spacing() const { return header_.spacing; }
  double value_offset() const { return value_offset_; }
  double value_scale() const { return value_scale_; }
  double error_fold() const { return header_.quantize_bits != 0 ? kQuantizationError : 0.0; }
  const StoreLayout& layout() const { return layout_; }
  const BrickIndexer& indexer() const { return indexer_; }
  BrickCache& cache() const { return cache_; }
  uint64_t bytes_read() const { return cache_.stats().bytes_read; }  // a distributed rank's load
  void will_read_again() const { cache_.keep_whole_budget(); }       // RereadHint

 private:
  // A scale-0 diamond's shape relative to its vertex, for one class of coordinates mod 4 (the
  // geometry of a vertex depends only on them, as BandTile's templates use): its polyhedron and the
  // refinement vertices of its children, as offsets.
  struct Band0Template {
    bool valid = false;
    int values = 0, children = 0;  // polyhedron: a, b, v, then the ring
    std::array<std::array<int8_t, 3>, 11> value{};
    std::array<std::array<int8_t, 3>, 12> child{};
    // What the topology of its record reads beyond the values: the polyhedron's type and shape
    // (the shape's tetrahedra per child depend on the levels below, the same for every lattice).
    PolyhedronType type = PolyhedronType::cube;
    DiamondShape shape;
  };

 public:
  // One per task: pins the bricks it used last (direct-mapped by brick index), so most lookups
  // touch no shared state at all.
  class Pager {
   public:
    explicit Pager(const PagedVolume& volume) : volume_(&volume) {}
    BrickValues values(int64_t index) { return brick(index).values(); }
    int band(int64_t index) { return brick(index).band(); }
    // Inline, as the lookups below: a traversal reads millions of records, nearly all of them
    // present and in a brick it holds.
    uint64_t bounds_word(int64_t index, uint32_t m) {
      const uint64_t w = word_of(brick(index), m);
      return w != kUnsetBounds ? w : computed_bounds_word(index, m);
    }
    DiamondBounds range_bound(int64_t index, uint32_t m) {
      const CachedBrick& b = brick(index);
      if (!b.narrow()) return isotope::range_bound(bounds_word(index, m));
      const uint32_t w = std::atomic_ref<uint32_t>(b.narrow_bounds()[m]).load(std::memory_order_relaxed);
      return narrow_range_bound(w != kUnsetNarrowBounds ? w : narrow_word(index, m));
    }
    Bf16 surplus(int64_t index, uint32_t m);
    DiamondTopology topology(int64_t index, uint32_t m, const RecordFields& read);
    // Whether read-ahead hints pay (BrickCache::hints_pay), and brick `index`'s core will be read
    // soon: the cache starts the kernel reading it.
    bool hints_pay() const { return volume_->cache_.hints_pay(); }
    void prefetch_brick(int64_t index) { volume_->cache_.prefetch(index); }
    void prefetch(int64_t index, uint32_t m) {
      const Pinned& p = pinned_[static_cast<size_t>(index) % pinned_.size()];
      if (p.index == index)
        __builtin_prefetch(p.brick->bounds_at(m));
      else
        prefetch_brick(index);
    }

   private:
    CachedBrick& brick(int64_t index) {
      Pinned& p = pinned_[static_cast<size_t>(index) % pinned_.size()];
      if (p.index != index) {
        p.brick = volume_->cache_.get(index);
        p.index = index;
      }
      return *p.brick;
    }
    std::shared_ptr<CachedBrick> hold(int64_t index) {
      brick(index);
      return pinned_[static_cast<size_t>(index) % pinned_.size()].brick;
    }
    // Band 0's record of node m of brick `index` (HOME, held by the caller), computed on first
    // read and stored there: its range and errors, its surplus where the brick holds it, and with
    // `topology` its intervals and its weights where the brick holds them. From the node's class
    // template when it lies inside the box by one node (band0_record_inside, band0_bounds_inside),
    // else from its diamond (band0_record).
    void compute_band0(CachedBrick& home, int64_t index, uint32_t m, bool topology);
    // compute_band0 of the node v through its diamond: any band-0 node.
    Record band0_record(const Coord& v, bool topology);
    // Whether v's polyhedron and its children lie in the data box (all but the box's outer layer
    // of nodes).
    bool inside_by_one(const Coord& v) const;
    // band0_record with `topology` of such a vertex, from its class's template (no diamond built,
    // the values within its brick read from it): the same record, bit for bit. (home, index, m):
    // where v's record lives, HOME held by the caller, as compute_band0's.
    Record band0_record_inside(const Coord& v, CachedBrick& home, int64_t index, uint32_t m);
    // band0_record without `topology` of such a vertex, the same way: its range and errors. A child
    // in HOME whose record is not computed yet is computed through HOME, with no lookup and no hold
    // of its own (as in band0_narrow_inside).
    void band0_bounds_inside(const Coord& v, CachedBrick& home, int64_t index, uint32_t m);
    // The nodes within one node of such a vertex, by their offset from it: whether they lie in its
    // brick, and where there. (Within the data box: the vertex lies inside it by one node.)
    struct Near {
      int64_t lx, ly, lz, mask;  // the vertex within its brick; the brick's width - 1
      [[gnu::always_inline]] bool in_brick(const std::array<int8_t, 3>& o) const {
        return static_cast<uint64_t>(lx + o[0]) <= static_cast<uint64_t>(mask) &&
               static_cast<uint64_t>(ly + o[1]) <= static_cast<uint64_t>(mask) &&
               static_cast<uint64_t>(lz + o[2]) <= static_cast<uint64_t>(mask);
      }
      [[gnu::always_inline]] uint32_t index(const std::array<int8_t, 3>& o) const {
        return kSpreadBits3[static_cast<size_t>(lx + o[0])] | kSpreadBits3[static_cast<size_t>(ly + o[1])] << 1 |
               kSpreadBits3[static_cast<size_t>(lz + o[2])] << 2;
      }
    };
    // v's template (v of scale 0), where v lies in its brick, and the values of its polyhedron in
    // the template's order (a, b, v, the ring), those in the brick read from it, with their range.
    const Band0Template& template_of(const Coord& v) const;
    Near near_of(const Coord& v) const;
    DiamondBounds polyhedron_values(const Coord& v, const Band0Template& t, const CachedBrick& home, const Near& near,
                                    float* f);
    // Where the record of the node at offset o from such a vertex lives: in the vertex's own
    // brick `index` (home) or another.
    struct Slot {
      int64_t index;
      uint32_t m;
      bool home;
    };
    Slot slot_near(const Coord& v, const std::array<int8_t, 3>& o, int64_t index, const Near& near) const;
    // band0_bounds_inside where the brick's words are narrow and it holds no surplus: in integers.
    void band0_narrow_inside(const Coord& v, const Band0Template& t, int64_t index, CachedBrick& home, uint32_t m,
                             const Near& near);
    float value_at(const Coord& c);  // as MultiresVolume::value: any lattice node, clamped into the data box
    // A record's range-and-bound word as bounds_word packs it, whatever width the
    // brick holds it in (CachedBrick::narrow), kUnsetBounds for one not computed yet; and storing one.
    uint64_t load_bounds(int64_t index, uint32_t m) { return word_of(brick(index), m); }
    static uint64_t word_of(const CachedBrick& b, uint32_t m) {
      if (!b.narrow()) return std::atomic_ref<uint64_t>(b.bounds()[m]).load(std::memory_order_relaxed);
      const uint32_t w = std::atomic_ref<uint32_t>(b.narrow_bounds()[m]).load(std::memory_order_relaxed);
      return w == kUnsetNarrowBounds ? kUnsetBounds : widen_bounds(w);
    }
    // bounds_word of a band-0 record not computed yet: computes it.
    uint64_t computed_bounds_word(int64_t index, uint32_t m);
    // bounds_word's narrow word, for a brick whose words are narrow (CachedBrick::narrow).
    uint32_t narrow_word(int64_t index, uint32_t m);
    void store_bounds(CachedBrick& home, uint32_t m, const PackedBounds& p);
    // The record fields a brick holds arrays for, taken once per band-0 record computed: the
    // children are read, the record computed and stored with those alone. An array another
    // thread's extraction adds meanwhile (BrickCache::require) stays unset for this record, and
    // that extraction computes it again, where a field computed without its children's would be
    // stored as if it were right.
    static RecordFields fields_held(const CachedBrick& home);
    // A child's record as a band-0 record reads it: range, bound, the surplus and (with
    // `topology`) the topology fields `held` names.
    Record child_record(int64_t index, uint32_t m, bool topology, const RecordFields& held);
    // A band-0 record computed into its brick: the fields `held` names, the bounds last.
    void store_band0_record(CachedBrick& home, uint32_t m, const Record& r, bool topology, const RecordFields& held);
    static Coord band0_node(const CachedBrick& brick, uint32_t m);  // band 0: the node of m in the brick

    struct Pinned {
      int64_t index = -1;
      std::shared_ptr<CachedBrick> brick;
    };
    const PagedVolume* volume_;
    std::array<Pinned, 32> pinned_;
  };

  class Reader : public CompactLookup<Pager> {
   public:
    explicit Reader(const PagedVolume& v) : CompactLookup(v.layout(), v.indexer(), Pager(v)) {}
  };
  Reader reader() const { return Reader(*this); }

 private:
  BrickCache& cache_;
  const StoreLayout& layout_;
  const StoreHeader& header_;
  BrickIndexer indexer_;
  double value_offset_ = 0, value_scale_ = 1;
  std::array<Band0Template, 64> band0_templates_;
};

class BudgetMemo;
// extract(), as over a MultiresVolume, over a store, paged through the volume's cache. `memo`: as
// extract_adaptive's, for a store kept open.
Mesh extract(const PagedVolume& volume, const ExtractCall& options, ExtractStats* stats = nullptr,
             BudgetMemo* memo = nullptr);

// The whole store in memory with the record fields asked for, every brick read as an extraction
// reads it (band 0's records computed from its values): what a store holds, made comparable with
// Hierarchy::build of its volume. Throws IoError naming a brick that cannot be read.
Hierarchy load_hierarchy(const PagedVolume& volume, const RecordFields& fields);

}  // namespace isotope
