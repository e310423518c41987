#pragma once
// The hierarchy built band by band, tile by tile (engine/hierarchy/band_tile.h), in memory bounded by a
// budget whatever the volume's size: band 0 from the volume's values, each band j > 0 from what
// band j-1 handed on (per node of G_j: its value, and the record of the cell's scale j-1 cube
// centre). The tiles of a band run in parallel, in batches sized to the budget; each brick is
// handed to a sink as soon as its tile is built (on the tile's thread), then committed in file
// order: bands 0 .. k, within a band bricks in Morton order (docs/FORMAT.md). What the sink keeps
// therefore depends on neither the thread count nor the budget.
//
// Two sinks: the in-memory hierarchy (engine/hierarchy/hierarchy.h), and the store writer (io/store/store_writer.cpp),
// which compresses the bricks and appends them to the file.
#include <algorithm>
#include <atomic>
#include <cstdint>
#include <functional>
#include <limits>
#include <memory>
#include <optional>
#include <utility>
#include <vector>

#include "engine/core/parallel.h"
#include "engine/core/progress.h"
#include "engine/hierarchy/band_tile.h"
#include "engine/hierarchy/store_layout.h"

namespace isotope {

// Band 0's input: the data nodes lo .. lo + size - 1 per axis, x fastest, into out. Called from
// several threads at once.
using ReadBox = std::function<void(const Box3& lo, const Box3& size, float* out)>;

// What band j hands band j+1: one entry per node of band j+1's grid, x fastest: the value, and the
// record of the cell's scale-j cube centre. Disjoint rows may be written and read concurrently.
class BandHandover {
 public:
  explicit BandHandover(const Box3& nodes) : nodes_(nodes) {}
  virtual ~BandHandover() = default;
  static uint64_t count(const Box3& n) { return static_cast<uint64_t>(n[0] * n[1] * n[2]); }
  static uint64_t bytes(const Box3& n) { return count(n) * (sizeof(float) + sizeof(Record)); }
  const Box3& nodes() const { return nodes_; }
  uint64_t at(int64_t x, int64_t y, int64_t z) const {
    return static_cast<uint64_t>((z * nodes_[1] + y) * nodes_[0] + x);
  }

  virtual void write_row(int64_t x0, int64_t y, int64_t z, const float* values, const Record* children, int64_t n) = 0;
  virtual void read_values(int64_t x0, int64_t count, int64_t y, int64_t z, float* out) const = 0;
  virtual void read_children(int64_t x0, int64_t count, int64_t y, int64_t z, Record* out) const = 0;

 private:
  Box3 nodes_;
};

class MemoryHandover : public BandHandover {
 public:
  explicit MemoryHandover(const Box3& nodes)
      : BandHandover(nodes),
        values_(std::make_unique_for_overwrite<float[]>(count(nodes))),
        children_(std::make_unique_for_overwrite<Record[]>(count(nodes))) {}
  void write_row(int64_t x0, int64_t y, int64_t z, const float* values, const Record* children, int64_t n) override {
    std::copy(values, values + n, values_.get() + at(x0, y, z));
    std::copy(children, children + n, children_.get() + at(x0, y, z));
  }
  void read_values(int64_t x0, int64_t count, int64_t y, int64_t z, float* out) const override {
    std::copy_n(values_.get() + at(x0, y, z), count, out);
  }
  void read_children(int64_t x0, int64_t count, int64_t y, int64_t z, Record* out) const override {
    std::copy_n(children_.get() + at(x0, y, z), count, out);
  }

 private:
  std::unique_ptr<float[]> values_;
  std::unique_ptr<Record[]> children_;
};

struct BandedBuildOptions {
  uint64_t memory_bytes = uint64_t{1} << 30;  // tiles in flight; a hand-over beyond a quarter of it may go elsewhere
  bool topology = true;                       // false: the records' range and errors only (BandTile::build)
  ProgressCallback progress;
  std::function<void()> check_cancel;  // called between batches; throws to stop
  // Where a band's hand-over goes; by default (or when this returns null) into memory.
  std::function<std::unique_ptr<BandHandover>(const Box3& nodes, uint64_t held_bytes)> make_handover;
  // One process's share of a distributed convert (io/store/store_writer.cpp): only bands
  // first_band .. last_band (-1: to the last), and of each only tiles [first_tile, last_tile) of
  // its Morton order, `tile_bricks` a side (0: chosen by tile_bricks_for). Band first_band > 0
  // reads `handover_in`; the last band built, when another follows, writes `handover_out`.
  int first_band = 0, last_band = -1;
  size_t first_tile = 0, last_tile = SIZE_MAX;
  int64_t tile_bricks = 0;
  const BandHandover* handover_in = nullptr;
  BandHandover* handover_out = nullptr;
};

struct BandedBuildStats {
  CriticalCounts critical = {{0, 0, 0}, {0, 0, 0}};
  float lo = std::numeric_limits<float>::infinity(), hi = -std::numeric_limits<float>::infinity();  // data values
  int tiles_in_flight = 0;
};

// The cells of a grid of `count` per axis in Morton order of their coordinates: bricks of a band
// in file (traversal) order, tiles of bricks, bricks in a tile.
std::vector<Box3> in_morton_order(const Box3& count);

// Bytes a tile of c^3 bricks holds while in flight: its window (values, records, children), and
// what the sink makes of its bricks (`brick_bytes` each, at most).
int64_t tile_bytes(const StoreLayout& layout, int64_t c, int64_t brick_bytes);

// Bricks per tile side that keep every thread busy within three quarters of the budget and give
// every thread a few tiles of band 0 (what build_bands uses unless told).
int64_t tile_bricks_for(const StoreLayout& layout, int64_t sink_brick_bytes, uint64_t memory_bytes);
// A band's tiles of c^3 bricks per axis, and how many (build_bands' first_tile and last_tile
// count them in Morton order).
inline Box3 tile_grid(const Band& band, int64_t c) {
  return {(band.bricks[0] + c - 1) / c, (band.bricks[1] + c - 1) / c, (band.bricks[2] + c - 1) / c};
}
inline size_t tile_count(const Band& band, int64_t c) {
  const Box3 g = tile_grid(band, c);
  return static_cast<size_t>(g[0] * g[1] * g[2]);
}

// Sink:
//   Payload process(int band, const Box3& brick, const BandTile& tile);  // concurrently, any order
//   void commit(int band, const Box3& brick, Payload&& payload);          // one at a time, in file order
// `sink_brick_bytes`: what one processed brick holds until committed (for the budget).
template <class Sink>
BandedBuildStats build_bands(const StoreLayout& layout, const ReadBox& read, Sink& sink, int64_t sink_brick_bytes,
                             const BandedBuildOptions& options);

// ---- Implementation ----------------------------------------------------------------------------

namespace banded_build_internal {

// Band 0's window: the data box part read from the input, the rest clamped to it.
void fill_from_input(BandTile& tile, const StoreLayout& layout, const ReadBox& read);
// Band j > 0's window, from band j-1's hand-over: values clamped to the grid, children where they exist.
void fill_from_handover(BandTile& tile, const BandHandover& in);
void write_next(const BandTile& tile, BandHandover& next);
void value_range(const BandTile& tile, const StoreLayout& layout, float& lo, float& hi);

template <class Payload>
struct TileResult {
  std::vector<std::pair<Box3, Payload>> bricks;
  CriticalCounts counts = {{0, 0, 0}, {0, 0, 0}};
  float lo = std::numeric_limits<float>::infinity(), hi = -std::numeric_limits<float>::infinity();
};

}  // namespace banded_build_internal

template <class Sink>
BandedBuildStats build_bands(const StoreLayout& layout, const ReadBox& read, Sink& sink, int64_t sink_brick_bytes,
                             const BandedBuildOptions& options) {
  using namespace banded_build_internal;
  using Payload = decltype(sink.process(0, Box3{}, std::declval<const BandTile&>()));
  const int64_t threads = thread_count();
  const auto budget = static_cast<int64_t>(options.memory_bytes / 4 * 3);
  const int64_t c =
      options.tile_bricks > 0 ? options.tile_bricks : tile_bricks_for(layout, sink_brick_bytes, options.memory_bytes);
  const int in_flight =
      static_cast<int>(std::clamp<int64_t>(budget / tile_bytes(layout, c, sink_brick_bytes), 1, 2 * threads));
  const int first_band = options.first_band;
  const int last_band = options.last_band < 0 ? layout.lattice().k : options.last_band;

  BandedBuildStats stats;
  stats.tiles_in_flight = in_flight;
  int64_t work = 0;
  for (const Band& b : layout.bands()) {
    if (b.scale < first_band || b.scale > last_band) continue;
    const size_t tiles = tile_count(b, c);
    const auto mine = static_cast<int64_t>(std::min(options.last_tile, tiles) - std::min(options.first_tile, tiles));
    // Near enough: edge tiles are smaller.
    work += b.nodes[0] * b.nodes[1] * b.nodes[2] / static_cast<int64_t>(tiles) * mine;
  }
  ProgressReporter progress(options.progress, work);
  // Band 0 has the largest windows; sized once for them, a slot's arrays never grow again (growing
  // would copy them and fault in fresh pages for every larger tile at the volume's edges).
  std::vector<BandTile::Buffers> buffers(static_cast<size_t>(in_flight));
  {
    size_t nodes = 1, cells = 1;
    for (int a = 0; a < 3; ++a) {
      const auto w = static_cast<size_t>(std::min(c * layout.brick_width(), layout.band(0).nodes[a]) + 4);
      nodes *= w;
      cells *= w - 1;
    }
    for (BandTile::Buffers& b : buffers) {
      b.values.resize(nodes);
      b.records.resize(nodes);
      b.children.resize(cells);
    }
  }
  std::unique_ptr<BandHandover> owned_in;
  const BandHandover* in = first_band > 0 ? options.handover_in : nullptr;
  for (const Band& band : layout.bands()) {
    if (band.scale < first_band || band.scale > last_band) continue;
    std::unique_ptr<BandHandover> owned_next;
    BandHandover* next = nullptr;
    if (band.scale < layout.lattice().k) {
      if (band.scale == last_band && options.handover_out) {
        next = options.handover_out;
      } else {
        const Box3& nodes = layout.band(band.scale + 1).nodes;
        const uint64_t held = BandHandover::bytes(nodes) + (in ? BandHandover::bytes(in->nodes()) : 0);
        if (options.make_handover) owned_next = options.make_handover(nodes, held);
        if (!owned_next) owned_next = std::make_unique<MemoryHandover>(nodes);
        next = owned_next.get();
      }
    }
    std::vector<Box3> tile_coords = in_morton_order(tile_grid(band, c));
    tile_coords = std::vector<Box3>(tile_coords.begin() + std::min(options.first_tile, tile_coords.size()),
                                    tile_coords.begin() + std::min(options.last_tile, tile_coords.size()));
    std::vector<TileResult<Payload>> results(static_cast<size_t>(in_flight));
    for (size_t first = 0; first < tile_coords.size(); first += results.size()) {
      if (options.check_cancel) options.check_cancel();
      const size_t count = std::min(results.size(), tile_coords.size() - first);
      parallel_for(int64_t{0}, static_cast<int64_t>(count), [&](int64_t i) {
        const auto slot = static_cast<size_t>(i);
        const Box3& tc = tile_coords[first + slot];
        const int64_t t = layout.brick_width();
        Box3 lo, hi;
        for (int a = 0; a < 3; ++a) {
          lo[a] = tc[a] * c * t;
          hi[a] = std::min(lo[a] + c * t, band.nodes[a]);
        }
        TileResult<Payload> r;
        BandTile tile(layout, band.scale, lo, hi, std::move(buffers[slot]));
        if (in)
          fill_from_handover(tile, *in);
        else
          fill_from_input(tile, layout, read);
        tile.build(r.counts, options.topology);
        if (next) write_next(tile, *next);
        if (band.scale == 0) value_range(tile, layout, r.lo, r.hi);
        // The tile's bricks in Morton order: with aligned power-of-two tiles taken in Morton order,
        // the band's bricks are committed in Morton order whatever the tile size.
        for (const Box3& l : in_morton_order({c, c, c})) {
          const Box3 b{tc[0] * c + l[0], tc[1] * c + l[1], tc[2] * c + l[2]};
          if (b[0] >= band.bricks[0] || b[1] >= band.bricks[1] || b[2] >= band.bricks[2]) continue;
          r.bricks.emplace_back(b, sink.process(band.scale, b, tile));
        }
        progress.advance((hi[0] - lo[0]) * (hi[1] - lo[1]) * (hi[2] - lo[2]));
        buffers[slot] = tile.release();
        results[slot] = std::move(r);
      });
      for (size_t i = 0; i < count; ++i) {
        TileResult<Payload>& r = results[i];
        for (auto& [b, payload] : r.bricks) sink.commit(band.scale, b, std::move(payload));
        r.bricks.clear();
        for (int t = 0; t < 3; ++t) {
          stats.critical[0][t] += r.counts[0][t];
          stats.critical[1][t] += r.counts[1][t];
        }
        stats.lo = std::min(stats.lo, r.lo);
        stats.hi = std::max(stats.hi, r.hi);
      }
    }
    owned_in = std::move(owned_next);
    in = next;
  }
  return stats;
}

}  // namespace isotope
