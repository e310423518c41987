#pragma once
// The hierarchy built band by band, tile by tile (BandTile), in memory bounded by a
// budget whatever the volume's size: band 0 from the volume's values, each band j > 0 from what
// band j-1 handed on (per node of G_j: its value, and the record of the cell's scale j-1 cube
// centre). The tiles of a band run in parallel, in batches sized to the budget; each brick is
// handed to a sink as soon as its tile is built (on the tile's thread), then committed in file
// order: bands 0 .. k, within a band bricks in Morton order (docs/FORMAT.md). What the sink keeps
// therefore depends on neither the thread count nor the budget.
//
// Two sinks: the in-memory hierarchy (Hierarchy), and the store writer (convert_to_store),
// which compresses the bricks and appends them to the file.
#include <algorithm>
#include <array>
#include <atomic>
#include <cstdint>
#include <cstring>
#include <functional>
#include <future>
#include <limits>
#include <memory>
#include <optional>
#include <stdexcept>
#include <tuple>
#include <utility>
#include <vector>

#include "engine/core/huge_blocks.h"
#include "engine/core/parallel.h"
#include "engine/core/progress_reporter.h"
#include "engine/hierarchy/band_tile.h"
#include "engine/hierarchy/store_layout.h"

namespace isotope {

// Band 0's input: the data nodes lo .. lo + size - 1 per axis, x fastest, into out. Called from
// several threads at once.
using ReadBox = std::function<void(const Box3& lo, const Box3& size, float* out)>;

// What band j hands band j+1: one entry per node of band j+1's grid: the value, and the record
// of the cell's scale-j cube centre. It is written and read a box at a time: nodes lo .. hi - 1 of
// the grid, in memory `row` entries from one row to the next and `plane` from one plane to the
// next (x fastest). Disjoint boxes may be written and read concurrently.
class BandHandover {
 public:
  explicit BandHandover(const Box3& nodes) : nodes_(nodes) {}
  virtual ~BandHandover() = default;
  static uint64_t count(const Box3& n) { return static_cast<uint64_t>(n[0] * n[1] * n[2]); }
  static uint64_t bytes(const Box3& n) { return count(n) * (sizeof(float) + sizeof(Record)); }
  const Box3& nodes() const { return nodes_; }

  // Whether a call costs a copy only (else a system call: a stage pays, below).
  virtual bool in_memory() const { return false; }
  // Whether it fits the build's budget. One that does not is never made where the bands on either
  // side of it can be built in one pass (BandedBuildOptions::fuse); one that does is kept, in
  // memory or not.
  virtual bool fits_budget() const { return in_memory(); }
  virtual void write_box(const Box3& lo, const Box3& hi, const float* values, const Record* children, int64_t row,
                         int64_t plane) = 0;
  virtual void read_values(const Box3& lo, const Box3& hi, float* out, int64_t row, int64_t plane) const = 0;
  virtual void read_children(const Box3& lo, const Box3& hi, Record* out, int64_t row, int64_t plane) const = 0;

 private:
  Box3 nodes_;
};

// The side of the cubes of entries a hand-over in a file keeps together (one call writes or reads
// a cube's planes): the boxes the tiles write are unions of them wherever a tile's part of the
// next band is a multiple of it (16, 32 or 64 nodes a side), and readers cut their boxes at its
// multiples along z.
inline constexpr int64_t kHandoverBlock = 16;

class MemoryHandover : public BandHandover {
 public:
  explicit MemoryHandover(const Box3& nodes)
      : BandHandover(nodes),
        values_(std::make_unique_for_overwrite<float[]>(count(nodes))),
        children_(static_cast<Record*>(::operator new(count(nodes) * sizeof(Record)))) {
    // Raw storage, not constructed: Record's members have initializers, which
    // make_unique_for_overwrite ran over the whole array on one thread before any tile started
    // (at 513^3, band 1's 750 MB took half a second). Every entry read was written by a tile
    // first; where assertions are on (the sanitizers' build) the storage starts as NaNs, so a
    // read of one never written would change what the tests compare. (Record is an aggregate, an
    // implicit-lifetime type: operator new's bytes are records.)
#ifndef NDEBUG
    std::memset(static_cast<void*>(children_.get()), 0xFF, count(nodes) * sizeof(Record));
#endif
    // Every page is written, a few rows at a time by the tiles: faulted in first, on all threads
    // (docs/METHOD.md, "Fresh memory").
    detail::prefault_in_parallel(values_.get(), count(nodes) * sizeof(float));
    detail::prefault_in_parallel(children_.get(), count(nodes) * sizeof(Record));
  }
  bool in_memory() const override { return true; }
  void write_box(const Box3& lo, const Box3& hi, const float* values, const Record* children, int64_t row,
                 int64_t plane) override {
    for_each_row(lo, hi, row, plane, [&](size_t at, int64_t from, int64_t n) {
      std::copy_n(values + from, n, values_.get() + at);
      std::copy_n(children + from, n, children_.get() + at);
    });
  }
  void read_values(const Box3& lo, const Box3& hi, float* out, int64_t row, int64_t plane) const override {
    for_each_row(lo, hi, row, plane,
                 [&](size_t at, int64_t to, int64_t n) { std::copy_n(values_.get() + at, n, out + to); });
  }
  void read_children(const Box3& lo, const Box3& hi, Record* out, int64_t row, int64_t plane) const override {
    for_each_row(lo, hi, row, plane,
                 [&](size_t at, int64_t to, int64_t n) { std::copy_n(children_.get() + at, n, out + to); });
  }

 private:
  // f(entry of the row's first node, its index in memory, nodes) for each row of the box.
  template <class F>
  void for_each_row(const Box3& lo, const Box3& hi, int64_t row, int64_t plane, const F& f) const {
    const Box3& n = nodes();
    for (int64_t z = lo[2]; z < hi[2]; ++z)
      for (int64_t y = lo[1]; y < hi[1]; ++y)
        f(static_cast<size_t>((z * n[1] + y) * n[0] + lo[0]), (z - lo[2]) * plane + (y - lo[1]) * row, hi[0] - lo[0]);
  }
  std::unique_ptr<float[]> values_;
  struct Free {  // what operator new gave
    void operator()(Record* p) const { ::operator delete(p); }
  };
  std::unique_ptr<Record[], Free> children_;
};

struct BandedBuildOptions {
  uint64_t memory_bytes = uint64_t{1} << 30;  // tiles in flight; a hand-over beyond a quarter of it may go elsewhere
  bool topology = true;                       // false: the records' range and errors only (BandTile::build)
  bool weights = true;                        // false: no simplification weights (BandTile::build)
  ProgressCallback progress;
  std::function<void()> check_cancel;  // called between batches; throws to stop
  // Where a band's hand-over goes; by default (or when this returns null) into memory.
  std::function<std::unique_ptr<BandHandover>(const Box3& nodes, uint64_t held_bytes)> make_handover;
  // One process's share of a distributed convert (convert_to_store): only bands
  // first_band .. last_band (-1: to the last), and of each only tiles [first_tile, last_tile) of
  // its Morton order, `tile_bricks` a side (0: chosen by tile_bricks_for). Band first_band > 0
  // reads `handover_in`; the last band built, when another follows, writes `handover_out`.
  int first_band = 0, last_band = -1;
  size_t first_tile = 0, last_tile = SIZE_MAX;
  int64_t tile_bricks = 0;
  const BandHandover* handover_in = nullptr;
  BandHandover* handover_out = nullptr;
  // Whether tiles read their input and hand-overs through a stage (below) where the budget has
  // room, in the bands whose hand-over in or out does not fit the budget: there a row costs a
  // system call; for a hand-over within it, in memory or in the page cache, a stage was one more
  // copy and its memory (embryo's HDF5 convert 0.95 -> 1.33 s with stages, 296 MB against 31 MB).
  bool staged = false;
  int64_t stage_tiles = 0;  // tiles a side of a staged group (a power of two); 0: as the budget allows
  // Whether band j+1 is built in band j's pass where the hand-over between them would not fit
  // the budget (make_handover gave one that does not: BandHandover::fits_budget): each tile of
  // band j, widened by a halo (kFuseBelow, kFuseAbove), hands a tile of band j+1 its window, so
  // that hand-over never exists, for a little work done twice (the halo). Needs a sink that holds
  // (below), tiles of an even number of bricks, and whole bands (no first_tile, last_tile).
  bool fuse = false;
  // A distributed convert's pass (convert_to_store): bands first_band and last_band =
  // first_band + 1 built as `fuse` builds them, over this process's run of band first_band's
  // tiles, whatever the hand-overs; `tile_bricks` even (fused_tile_bricks_for). The caller places
  // the held bricks.
  bool fuse_pair = false;
};

// How far a tile of band j reaches beyond its core when it hands band j+1's tile its window
// (G_{j+1} nodes L-1 .. H+1 and cells L-1 .. H for a core L .. H-1, L even: BandTile::window_of):
// that window's children, band j's cube centres 2g + 1, are records of band j's nodes 2L-1 .. 2H+1,
// its values reach 2H+2, in the window of the widened core.
inline constexpr int64_t kFuseBelow = 1, kFuseAbove = 2;
inline constexpr int64_t kFusedSide = 64;  // the least tile side (nodes) fused when the tile size is not given

struct BandedBuildStats {
  CriticalCounts critical = {{0, 0, 0}, {0, 0, 0}};
  float lo = std::numeric_limits<float>::infinity(), hi = -std::numeric_limits<float>::infinity();  // data values
  int tiles_in_flight = 0;
  int bands_built_beside = 0;  // in the pass of the band before them: their hand-over never existed
};

// The cells of a grid of `count` per axis in Morton order of their coordinates: bricks of a band
// in file (traversal) order, tiles of bricks, bricks in a tile.
std::vector<Box3> in_morton_order(const Box3& count);

// Bytes a tile of c^3 bricks holds while in flight: its window (values, records, children), and
// what the sink makes of its bricks (`brick_bytes` each, at most); fused, with band j+1's tile.
int64_t tile_bytes(const StoreLayout& layout, int64_t c, int64_t brick_bytes, bool fused = false);

// Bricks per tile side that keep every thread busy within three quarters of the budget and give
// every thread a few tiles of band 0 (what build_bands uses unless told): up to 32 nodes a side,
// fused up to 128.
int64_t tile_bricks_for(const StoreLayout& layout, int64_t sink_brick_bytes, uint64_t memory_bytes, bool fused = false);
// tile_bricks_for's fused tile, where band j+1 can be built in band j's pass with it: an even
// count of at least kFusedSide nodes a side; else 0.
int64_t fused_tile_bricks_for(const StoreLayout& layout, int64_t sink_brick_bytes, uint64_t memory_bytes);
// A band's own tile side, at most c bricks (a power of two): halved while the band's nodes would
// make fewer than kFullTilesAThread full tiles a thread, so that a small band (the coarse bands, or
// band 0 of a small volume, whose grid is one tile of c and thin ones at its far faces) is not one
// thread's work while the others wait, and its tiles in flight fault in less fresh memory. On one
// thread, c.
int64_t band_tile_bricks(const StoreLayout& layout, const Band& band, int64_t c);
// Sixteen: a band of 66^3-123^3 nodes (the shared volumes' band 0) takes tiles of 16^3 nodes, not
// 32^3, whose windows' records (20^3 against 36^3 of them, 44 bytes each, in each of the tiles in
// flight) cost more to fault in than the halo records the smaller tiles compute twice: their
// converts 5-11% faster on two threads, a quarter less peak memory; larger volumes unchanged
// within the noise (docs/METHOD.md, "Per-vertex records").
inline constexpr double kFullTilesAThread = 16;
// Tiles per side of a staged group (below: a power of two, aligned, so that a group is a run of
// the band's Morton order) whose stage fits in `room` bytes; 0 when not even two a side fit.
int64_t stage_tiles_for(const StoreLayout& layout, int band, int64_t c, uint64_t room, bool fused = false);
// A band's tiles of c^3 bricks per axis, and how many (build_bands' first_tile and last_tile
// count them in Morton order).
inline Box3 tile_grid(const Band& band, int64_t c) {
  return {(band.bricks[0] + c - 1) / c, (band.bricks[1] + c - 1) / c, (band.bricks[2] + c - 1) / c};
}
inline size_t tile_count(const Band& band, int64_t c) {
  const Box3 g = tile_grid(band, c);
  return static_cast<size_t>(g[0] * g[1] * g[2]);
}
// The band's nodes in each tile's core, in that order: what a tile costs to build. The tiles at
// the grid's far faces are thin (a 513^3 volume's band 0 has 8 full tiles of 64 nodes a side and
// one of a single node), and Morton order puts them last: shares of equal tile counts gave the
// last rank half the work of the first.
std::vector<double> tile_costs(const StoreLayout& layout, const Band& band, int64_t c);

// Sink:
//   Payload process(int band, const Box3& brick, const BandTile& tile);  // concurrently, any order
//   void commit(int band, const Box3& brick, Payload&& payload);          // one at a time, in file order
//   void hold(int band, const Box3& brick, Payload&& payload);  // one at a time: band j+1's bricks of a
//                                                              // fused pass, in no particular order
//   void release();  // after band j's last commit: what was held, committed in file order
// `sink_brick_bytes`: what one processed brick holds until committed (for the budget).
template <class Sink>
BandedBuildStats build_bands(const StoreLayout& layout, const ReadBox& read, Sink& sink, int64_t sink_brick_bytes,
                             const BandedBuildOptions& options);

// ---- Implementation ----------------------------------------------------------------------------

namespace banded_build_internal {

// Band j > 0's window read row by row from band j-1's hand-over into the tile, as StagedBox
// would fill it (without a stage: no box beside the tile's own arrays).
void fill_from_handover(BandTile& tile, const BandHandover& in);
void write_next(const BandTile& tile, BandHandover& next);
void value_range(const BandTile& tile, const StoreLayout& layout, float& lo, float& hi);

// The stage: the reads of a group of tiles gathered into one box of the band's grid, read at
// once (one call per row of the box, or per plane when the box spans whole rows) and copied
// into each tile's window; and what the group hands the next band, gathered so that each row is
// written once. A tile's window is its own box otherwise. Whatever the box, a tile's window holds
// the same entries, so the stage changes no byte of the output.
class StagedBox {
 public:
  // The union lo .. hi (inclusive) of the windows of tiles of band 0, values read from the
  // input of `dims` nodes a side.
  void read_input(const Box3& lo, const Box3& hi, const Box3& dims, const ReadBox& read);
  // Of tiles of band j > 0: values and the children of the cells, from band j-1's hand-over.
  void read_handover(const Box3& lo, const Box3& hi, const BandHandover& in);
  // The window of `to`, a tile of band j+1 built beside band j (a fused pass), from `from`, a
  // tile of band j whose core holds the records it needs (kFuseBelow, kFuseAbove).
  void take_next(const BandTile& from, const BandTile& to);
  // The window of a tile inside the box: its values clamped to the grid, its children where
  // their corner node lies in the grid.
  void fill(BandTile& tile) const;
  static uint64_t bytes(const Box3& size, bool children);  // a box of size[a] nodes a side

 private:
  // The box lo .. hi clamped to the grid, its values' room, and with `children` its cells.
  void frame(const Box3& lo, const Box3& hi, const Box3& grid, bool children);
  Box3 grid_{}, lo_{}, size_{};   // values: nodes lo_ .. lo_ + size_ - 1 of a grid of grid_
  Box3 cell_lo_{}, cell_size_{};  // children: cells cell_lo_ .. cell_lo_ + cell_size_ - 1
  bool children_ = false;
  std::vector<float> values_;
  std::vector<Record> records_;
};

// What a group of tiles hands band j + 1: nodes lo .. hi - 1 of its grid, each tile's part
// written by that tile (disjoint: concurrently), then every row the tiles cover written once.
class StagedNext {
 public:
  void reset(const Box3& lo, const Box3& hi);
  void take(const BandTile& tile);
  // Rows of the tiles' boxes only (under a distribution, the rest of the box may be another
  // process's), each maximal run of tiles along x in one call per row.
  void write(const std::vector<std::pair<Box3, Box3>>& tile_boxes, BandHandover& next) const;
  static uint64_t bytes(const Box3& size);  // rows of a box of size[a] nodes a side

 private:
  size_t index(int64_t x, int64_t y, int64_t z) const {
    return static_cast<size_t>(((z - lo_[2]) * size_[1] + (y - lo_[1])) * size_[0] + (x - lo_[0]));
  }
  Box3 lo_{}, size_{};
  std::vector<float> values_;
  std::vector<Record> children_;
};

template <class Payload>
struct TileResult {
  std::vector<std::pair<Box3, Payload>> bricks, held;  // of band j, and of band j+1 in a fused pass
  CriticalCounts counts = {{0, 0, 0}, {0, 0, 0}};
  float lo = std::numeric_limits<float>::infinity(), hi = -std::numeric_limits<float>::infinity();
};

}  // namespace banded_build_internal

namespace banded_build_internal {

// build_bands as named passes over the state they share: the tiles chosen and their slots
// reserved once; then each band opened (its hand-over, fused with the band above or not, its
// tiles), its groups of tiles staged, built and committed in order, and what they hand on written.
template <class Sink>
class BandedBuild {
 public:
  using Payload = decltype(std::declval<Sink&>().process(0, Box3{}, std::declval<const BandTile&>()));

  BandedBuild(const StoreLayout& layout, const ReadBox& read, Sink& sink, int64_t sink_brick_bytes,
              const BandedBuildOptions& options)
      : layout_(layout),
        read_(read),
        sink_(sink),
        sink_brick_bytes_(sink_brick_bytes),
        options_(options),
        threads_(thread_count()),
        budget_(static_cast<int64_t>(options.memory_bytes / 4 * 3)),
        first_band_(options.first_band),
        last_band_(options.last_band < 0 ? layout.lattice().k : options.last_band),
        k_(layout.lattice().k),
        width_(layout.brick_width()) {}

  BandedBuildStats run() {
    choose_tiles();
    reserve_slots();
    in_ = first_band_ > 0 ? options_.handover_in : nullptr;
    for (const Band& band : layout_.bands()) {
      const int j = band.scale;
      if (j < first_band_ || j > last_band_ || j == built_beside_) continue;
      BandPass pass;
      open_band(band, pass);
      for (size_t group = 0; group < pass.tiles.size();) {
        const size_t group_end = stage_group(pass, group);
        build_group(pass, group, group_end);
        hand_on_group(pass);
        group = group_end;
      }
      close_band(pass);
    }
    return stats_;
  }

 private:
  // One band's pass.
  struct BandPass {
    const Band* band = nullptr;
    int j = 0;
    bool fuse = false;                         // band j+1 built beside band j
    const Band* upper = nullptr;               // that band
    BandHandover* next = nullptr;              // what the pass hands on (band j+1's, or fused j+2's)
    std::unique_ptr<BandHandover> owned_next;  // that hand-over, where this build made it
    int64_t c = 0, side = 0;                   // the band's tiles: c^3 bricks, side nodes
    std::vector<Box3> tiles;                   // their coordinates, in Morton order
    int64_t stage_side = 0;                    // tiles a side of a staged group; 0: no stage
    std::vector<TileResult<Payload>> results;  // a slot's
    std::future<void> writing;                 // a group's rows to `next`; waited for before the band's end
  };

  // The tile size, whether passes will fuse, and the tiles in flight. Band j+1's tiles are c/2 of
  // its bricks a side: c even. Chosen here, fused passes only with tiles of kFusedSide nodes or
  // more: the halo computed twice costs less than the hand-over's file (at 64^3, 15% more of band
  // j's work; at 32^3, 31%). Whether a pass will be fused at all: band 0's hand-over, the largest,
  // would be a file (each later one, with the one before it, is smaller than band 0's alone). The
  // hand-over asked for is band 1's own, taken when band 0 hands over (handover_to, below).
  void choose_tiles() {
    const bool may_fuse = options_.fuse && options_.first_tile == 0 && options_.last_tile == SIZE_MAX;
    bool fusing = may_fuse && options_.first_band == 0 && k_ >= 1 && options_.make_handover;
    if (fusing) {
      const Box3& nodes = layout_.band(1).nodes;
      probe_ = options_.make_handover(nodes, BandHandover::bytes(nodes));
      fusing = probe_ && !probe_->fits_budget();
    }
    c_ = options_.tile_bricks;
    if (options_.fuse_pair && (c_ <= 0 || c_ % 2 != 0 || options_.last_band != options_.first_band + 1))
      throw std::logic_error("build_bands: a fused pair is two bands in tiles of an even number of bricks");
    can_fuse_ = (fusing || options_.fuse_pair) && c_ % 2 == 0;
    plain_c_ = c_;
    if (c_ <= 0) {
      c_ = plain_c_ = tile_bricks_for(layout_, sink_brick_bytes_, options_.memory_bytes);
      const int64_t fused = fusing ? fused_tile_bricks_for(layout_, sink_brick_bytes_, options_.memory_bytes) : 0;
      can_fuse_ = fused > 0;
      if (can_fuse_) c_ = fused;
    }
    in_flight_ = static_cast<int>(
        std::clamp<int64_t>(budget_ / tile_bytes(layout_, c_, sink_brick_bytes_, can_fuse_), 1, 2 * threads_));
    stats_.tiles_in_flight = in_flight_;
    int64_t work = 0;
    for (const Band& b : layout_.bands()) {
      if (b.scale < first_band_ || b.scale > last_band_) continue;
      const size_t tiles = tile_count(b, c_);
      const auto mine =
          static_cast<int64_t>(std::min(options_.last_tile, tiles) - std::min(options_.first_tile, tiles));
      // Near enough: edge tiles are smaller.
      work += b.nodes[0] * b.nodes[1] * b.nodes[2] / static_cast<int64_t>(tiles) * mine;
    }
    progress_.emplace(options_.progress, work);
  }

  // Band 0 has the largest windows; reserved once for them, a slot's arrays never move again
  // (growing would copy them and fault in fresh pages for every larger tile at the volume's edges).
  // Reserved, not filled: a page is faulted in by the first tile that uses it, and band 0, which has
  // no children, leaves the children's untouched (a small volume's slots seldom hold a higher band).
  // What the tiles in flight leave of the budget goes to the stage.
  void reserve_slots() {
    auto reserved = [](const Box3& core, const Box3& grid) {
      size_t nodes = 1, cells = 1;
      for (int a = 0; a < 3; ++a) {
        const auto w = static_cast<size_t>(std::min(core[a], grid[a]) + 4);
        nodes *= w;
        cells *= w - 1;
      }
      BandTile::Buffers b;
      b.values.reserve(nodes);
      b.records.reserve(nodes);
      b.children.reserve(cells);
      return b;
    };
    const int64_t widened = c_ * width_ + (can_fuse_ ? kFuseBelow + kFuseAbove : 0);
    handed_.resize(can_fuse_ ? static_cast<size_t>(in_flight_) : 0);
    for (int i = 0; i < in_flight_; ++i) {
      buffers_.push_back(reserved({widened, widened, widened}, layout_.band(0).nodes));
      if (can_fuse_ && k_ > 0)
        upper_buffers_.push_back(
            reserved({c_ * width_ / 2 + 1, c_ * width_ / 2 + 1, c_ * width_ / 2 + 1}, layout_.band(1).nodes));
    }
    const int64_t tiles_held = in_flight_ * tile_bytes(layout_, c_, sink_brick_bytes_, can_fuse_);
    stage_room_ = static_cast<uint64_t>(std::max<int64_t>(0, budget_ - tiles_held));
  }

  // The hand-over band `to` reads: the one asked for after the last band, else as make_handover
  // chooses (in memory by default).
  BandHandover* handover_to(int to, BandPass& pass) {
    if (to - 1 == last_band_ && options_.handover_out) return options_.handover_out;
    const Box3& nodes = layout_.band(to).nodes;
    const uint64_t held = BandHandover::bytes(nodes) + (in_ ? BandHandover::bytes(in_->nodes()) : 0);
    if (to == 1 && probe_)
      pass.owned_next = std::move(probe_);  // asked for with the same bytes held (band 0 reads none)
    else if (options_.make_handover)
      pass.owned_next = options_.make_handover(nodes, held);
    if (!pass.owned_next) pass.owned_next = std::make_unique<MemoryHandover>(nodes);
    return pass.owned_next.get();
  }

  // A fused pass: bands j and j+1, whose hand-over would have been a file (or a distributed
  // convert's pair, whose hand-over would be shared: never made). Its tiles, of the chosen side (a
  // fused pass's, or tiles counted by the caller), else the band's own; and its groups: the tiles
  // of one aligned cube of s^3 tiles, which share a stage, where a hand-over in or out does not
  // fit the budget; without a stage, the band's tiles.
  void open_band(const Band& band, BandPass& pass) {
    const int j = band.scale;
    pass.band = &band;
    pass.j = j;
    const bool pair = options_.fuse_pair && j == first_band_;
    pass.next = j < k_ && !pair ? handover_to(j + 1, pass) : nullptr;
    pass.fuse = pair || (can_fuse_ && pass.next && pass.next == pass.owned_next.get() && !pass.next->fits_budget() &&
                         j + 1 <= last_band_);
    if (pass.fuse) {
      pass.owned_next.reset();
      pass.next = j + 1 < k_ ? handover_to(j + 2, pass) : nullptr;
      built_beside_ = j + 1;
      ++stats_.bands_built_beside;
    }
    pass.upper = pass.fuse ? &layout_.band(j + 1) : nullptr;
    const bool whole_band = options_.tile_bricks <= 0 && options_.first_tile == 0 && options_.last_tile == SIZE_MAX;
    pass.c = pass.fuse || !whole_band ? c_ : band_tile_bricks(layout_, band, std::min(c_, plain_c_));
    pass.side = pass.c * width_;
    const std::vector<Box3> all = in_morton_order(tile_grid(band, pass.c));
    pass.tiles = std::vector<Box3>(all.begin() + std::min(options_.first_tile, all.size()),
                                   all.begin() + std::min(options_.last_tile, all.size()));
    const bool costly = (in_ && !in_->fits_budget()) || (pass.next && !pass.next->fits_budget());
    pass.stage_side = !options_.staged || !costly ? 0
                      : options_.stage_tiles > 0  ? options_.stage_tiles
                                                  : stage_tiles_for(layout_, j, pass.c, stage_room_, pass.fuse);
    pass.results.resize(static_cast<size_t>(in_flight_));
  }

  // A tile's core in band j's grid.
  std::pair<Box3, Box3> core_of(const BandPass& pass, const Box3& tc) const {
    Box3 lo, hi;
    for (int a = 0; a < 3; ++a) {
      lo[a] = tc[a] * pass.side;
      hi[a] = std::min(lo[a] + pass.side, pass.band->nodes[a]);
    }
    return {lo, hi};
  }
  // Of a fused pass: the core band j's tile computes (its own widened by the halo band j+1's
  // tile needs), and that tile's core (up to band j+1's last node at the grid's far faces).
  std::pair<Box3, Box3> widened_of(const BandPass& pass, const Box3& lo, const Box3& hi) const {
    Box3 wlo, whi;
    for (int a = 0; a < 3; ++a) {
      wlo[a] = std::max<int64_t>(0, lo[a] - kFuseBelow);
      whi[a] = std::min(hi[a] + kFuseAbove, pass.band->nodes[a]);
    }
    return {wlo, whi};
  }
  std::pair<Box3, Box3> upper_of(const BandPass& pass, const Box3& lo, const Box3& hi) const {
    Box3 ulo, uhi;
    for (int a = 0; a < 3; ++a) {
      ulo[a] = lo[a] / 2;
      uhi[a] = hi[a] == pass.band->nodes[a] ? pass.upper->nodes[a] : hi[a] / 2;
    }
    return {ulo, uhi};
  }

  // The group from tile `group` on: with a stage, the tiles of its aligned cube, their windows
  // read into the stage at once, and what they hand on gathered; without one, the whole band in
  // one run: the tiles in flight are bounded by the commits (parallel_in_order_committed), and a
  // run ended every few tiles would leave a thread idle at each end, waiting for the slowest tile
  // of the run. Returns the group's end.
  size_t stage_group(BandPass& pass, size_t group) {
    const int64_t s = pass.stage_side;
    if (s == 0) return pass.tiles.size();
    size_t group_end = group + 1;
    auto cube = [s](const Box3& tc) { return Box3{tc[0] / s, tc[1] / s, tc[2] / s}; };
    while (group_end < pass.tiles.size() && cube(pass.tiles[group_end]) == cube(pass.tiles[group])) ++group_end;
    Box3 lo{INT64_MAX, INT64_MAX, INT64_MAX}, hi{0, 0, 0}, next_lo = lo, next_hi = hi;
    tile_boxes_.clear();
    for (size_t i = group; i < group_end; ++i) {
      auto [core_lo, core_hi] = core_of(pass, pass.tiles[i]);
      auto [nlo, nhi] = BandTile::next_of(layout_, pass.j, core_lo, core_hi);
      if (pass.fuse) {
        const auto [ulo, uhi] = upper_of(pass, core_lo, core_hi);
        std::tie(nlo, nhi) = BandTile::next_of(layout_, pass.j + 1, ulo, uhi);
        std::tie(core_lo, core_hi) = widened_of(pass, core_lo, core_hi);
      }
      const auto [wlo, whi] = BandTile::window_of(layout_, pass.j, core_lo, core_hi);
      tile_boxes_.emplace_back(nlo, nhi);
      for (int a = 0; a < 3; ++a) {
        lo[a] = std::min(lo[a], wlo[a]);
        hi[a] = std::max(hi[a], whi[a]);
        next_lo[a] = std::min(next_lo[a], nlo[a]);
        next_hi[a] = std::max(next_hi[a], nhi[a]);
      }
    }
    if (in_)
      stage_.read_handover(lo, hi, *in_);
    else
      stage_.read_input(lo, hi, layout_.dims(), read_);
    if (pass.next) staged_next_[writing_to_].reset(next_lo, next_hi);
    return group_end;
  }

  // Tiles built ahead of the commits by at most the tiles in flight, each in its slot; their
  // bricks committed in the band's Morton order.
  void build_group(BandPass& pass, size_t group, size_t group_end) {
    const auto slot_of = [&](int64_t i) {
      return static_cast<size_t>(i - static_cast<int64_t>(group)) % pass.results.size();
    };
    parallel_in_order_committed(
        static_cast<int64_t>(group), static_cast<int64_t>(group_end), static_cast<int64_t>(pass.results.size()),
        [&](int64_t i) { build_tile(pass, pass.tiles[static_cast<size_t>(i)], slot_of(i)); },
        [&](int64_t i) { commit_tile(pass, pass.results[slot_of(i)]); });
  }

  void build_tile(BandPass& pass, const Box3& tc, size_t slot) {
    if (options_.check_cancel) options_.check_cancel();
    const int j = pass.j;
    const Band& band = *pass.band;
    const auto [lo, hi] = core_of(pass, tc);
    const auto [clo, chi] = pass.fuse ? widened_of(pass, lo, hi) : std::pair{lo, hi};
    TileResult<Payload> r;
    BandTile tile(layout_, j, clo, chi, std::move(buffers_[slot]));
    tile.count_only(lo, hi);
    if (pass.stage_side > 0) {
      stage_.fill(tile);
    } else if (in_) {
      fill_from_handover(tile, *in_);
    } else {
      thread_local StagedBox own;  // the tile's window alone
      own.read_input(tile.window_lo(), tile.window_hi(), layout_.dims(), read_);
      own.fill(tile);
    }
    tile.build(r.counts, options_.topology, options_.weights);
    if (j == 0) value_range(tile, layout_, r.lo, r.hi);
    // A tile's bricks in Morton order: with aligned power-of-two tiles taken in Morton order,
    // the band's bricks are committed in Morton order whatever the tile size.
    for (const Box3& l : in_morton_order({pass.c, pass.c, pass.c})) {
      const Box3 b{tc[0] * pass.c + l[0], tc[1] * pass.c + l[1], tc[2] * pass.c + l[2]};
      if (b[0] >= band.bricks[0] || b[1] >= band.bricks[1] || b[2] >= band.bricks[2]) continue;
      r.bricks.emplace_back(b, sink_.process(j, b, tile));
    }
    progress_->advance((hi[0] - lo[0]) * (hi[1] - lo[1]) * (hi[2] - lo[2]));
    std::optional<BandTile> beside;  // band j+1's tile of a fused pass
    if (pass.fuse) {
      const auto [ulo, uhi] = upper_of(pass, lo, hi);
      beside.emplace(layout_, j + 1, ulo, uhi, std::move(upper_buffers_[slot]));
      handed_[slot].take_next(tile, *beside);
      handed_[slot].fill(*beside);
      beside->build(r.counts, options_.topology, options_.weights);
      // Its bricks: those whose first node is in its core (at the far faces, beyond c/2).
      Box3 first_brick, bricks;
      for (int a = 0; a < 3; ++a) {
        first_brick[a] = ulo[a] / width_;
        bricks[a] = (uhi[a] - 1) / width_ + 1 - first_brick[a];
      }
      for (const Box3& l : in_morton_order(bricks)) {
        const Box3 b{first_brick[0] + l[0], first_brick[1] + l[1], first_brick[2] + l[2]};
        r.held.emplace_back(b, sink_.process(j + 1, b, *beside));
      }
      progress_->advance((uhi[0] - ulo[0]) * (uhi[1] - ulo[1]) * (uhi[2] - ulo[2]));
    }
    const BandTile& handing = beside ? *beside : tile;  // what `next` reads: band j+1's (or j+2's) nodes
    if (pass.next && pass.stage_side > 0)
      staged_next_[writing_to_].take(handing);
    else if (pass.next)
      write_next(handing, *pass.next);
    buffers_[slot] = tile.release();
    if (beside) upper_buffers_[slot] = beside->release();
    pass.results[slot] = std::move(r);
  }

  void commit_tile(const BandPass& pass, TileResult<Payload>& r) {
    for (auto& [b, payload] : r.bricks) sink_.commit(pass.j, b, std::move(payload));
    for (auto& [b, payload] : r.held) sink_.hold(pass.j + 1, b, std::move(payload));
    r.bricks.clear();
    r.held.clear();
    for (int t = 0; t < 3; ++t) {
      stats_.critical[0][t] += r.counts[0][t];
      stats_.critical[1][t] += r.counts[1][t];
    }
    stats_.lo = std::min(stats_.lo, r.lo);
    stats_.hi = std::max(stats_.hi, r.hi);
  }

  // A staged group's rows, written on a thread of their own while the next group is built (the
  // writes hold the file's lock, and would leave the other workers idle).
  void hand_on_group(BandPass& pass) {
    if (!pass.next || pass.stage_side == 0) return;
    if (pass.writing.valid()) pass.writing.get();  // rethrows what failed
    if (threads_ > 1) {
      pass.writing = std::async(std::launch::async, [this, next = pass.next, i = writing_to_, boxes = tile_boxes_] {
        staged_next_[i].write(boxes, *next);
      });
      writing_to_ ^= 1;
    } else {
      staged_next_[writing_to_].write(tile_boxes_, *pass.next);
    }
  }

  void close_band(BandPass& pass) {
    if (pass.writing.valid()) pass.writing.get();
    if (pass.fuse) sink_.release();
    owned_in_ = std::move(pass.owned_next);
    in_ = pass.next;
  }

  const StoreLayout& layout_;
  const ReadBox& read_;
  Sink& sink_;
  const int64_t sink_brick_bytes_;
  const BandedBuildOptions& options_;
  const int64_t threads_, budget_;
  const int first_band_, last_band_, k_;
  const int64_t width_;
  std::optional<ProgressReporter> progress_;
  std::unique_ptr<BandHandover> probe_;  // band 1's hand-over, asked for to learn whether passes fuse
  int64_t c_ = 0, plain_c_ = 0;          // the tiles of a fused pass, and of one that is not
  bool can_fuse_ = false;
  int in_flight_ = 1;
  BandedBuildStats stats_;
  std::vector<BandTile::Buffers> buffers_, upper_buffers_;  // a slot's tile's, and its band j+1 tile's
  std::vector<StagedBox> handed_;                           // band j to j+1, in a fused pass
  uint64_t stage_room_ = 0;
  StagedBox stage_;
  // Two: a group's rows are written on a thread of their own while the next group is built.
  std::array<StagedNext, 2> staged_next_;
  size_t writing_to_ = 0;
  std::vector<std::pair<Box3, Box3>> tile_boxes_;  // a group's boxes of the band it hands on to
  std::unique_ptr<BandHandover> owned_in_;
  const BandHandover* in_ = nullptr;
  int built_beside_ = -1;  // the band built in the pass of the band before it
};

}  // namespace banded_build_internal

template <class Sink>
BandedBuildStats build_bands(const StoreLayout& layout, const ReadBox& read, Sink& sink, int64_t sink_brick_bytes,
                             const BandedBuildOptions& options) {
  return banded_build_internal::BandedBuild<Sink>(layout, read, sink, sink_brick_bytes, options).run();
}

}  // namespace isotope
