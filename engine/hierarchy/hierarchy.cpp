#include "engine/hierarchy/hierarchy.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <string>

#include "engine/core/huge_blocks.h"
#include "engine/core/volume_check.h"
#include "engine/hierarchy/band_tile.h"
#include "engine/hierarchy/banded_build.h"
#include "engine/hierarchy/record_builder.h"

namespace isotope {

BrickIndexer::BrickIndexer(const StoreLayout& layout) : bits_(layout.brick_bits()) {
  mask_ = layout.brick_width() - 1;
  nodes_ = layout.brick_nodes();
  for (const Band& b : layout.bands())
    band_[static_cast<size_t>(b.scale)] = {b.first_brick, b.bricks[0], b.bricks[1], b.nodes};
}

void store_record(const BrickView& brick, uint32_t m, const Record& r) {
  brick.bounds[m] = bounds_word(pack_bounds(r.bounds));
  if (!brick.surplus && !brick.exact && !brick.paper && !brick.weights) return;
  const PackedTopology t = pack_topology(r.topology, r.bounds.error_surplus);
  if (brick.surplus) brick.surplus[m] = t.surplus;
  if (brick.exact) brick.exact[m] = interval_word(t.exact_lo, t.exact_hi);
  if (brick.paper) brick.paper[m] = interval_word(t.paper_lo, t.paper_hi);
  if (brick.weights) brick.weights[m] = weights_word(t.weight);
}

void fill_brick(const BandTile& tile, const Box3& origin, const BrickView& out, float* values) {
  const StoreLayout& layout = tile.layout();
  const Band& band = layout.band(tile.band());
  const bool records = tile.band() < layout.lattice().k;  // the corners have none: all absent
  const Record absent{DiamondBounds{0, 0, 0, 0}, DiamondTopology{0, 0, 0, 0, {0, 0, 0}}};
  const int64_t t = layout.brick_width();
  const Box3 end{std::min(t, band.nodes[0] - origin[0]), std::min(t, band.nodes[1] - origin[1]),
                 std::min(t, band.nodes[2] - origin[2])};
  // A brick past the band's grid: its nodes beyond it absent, value 0, before the others are written.
  if (end[0] < t || end[1] < t || end[2] < t)
    for (uint32_t m = 0; m < static_cast<uint32_t>(layout.brick_nodes()); ++m) {
      values[m] = 0.0f;
      store_record(out, m, absent);
    }
  // Row by row of the tile's window (x fastest), each node written at its Morton place in the
  // brick.
  for (int64_t z = 0; z < end[2]; ++z)
    for (int64_t y = 0; y < end[1]; ++y) {
      const uint32_t yz = kSpreadBits3[static_cast<size_t>(y)] << 1 | kSpreadBits3[static_cast<size_t>(z)] << 2;
      const Box3 first{origin[0], origin[1] + y, origin[2] + z};
      const float* row_values = &tile.node_value(first);
      const Record* row_records = &tile.node_record(first);
      for (int64_t x = 0; x < end[0]; ++x) {
        const uint32_t m = yz | kSpreadBits3[static_cast<size_t>(x)];
        values[m] = row_values[x];
        // Coarser nodes' entries (all coordinates even) are never read; written all the same.
        store_record(out, m, (m & 7) == 0 || !records ? absent : row_records[x]);
      }
    }
}

Hierarchy Hierarchy::allocate(const std::array<int64_t, 3>& dims, int brick_bits, const RecordFields& fields) {
  validate_dims(dims);
  Hierarchy h;
  h.layout_ = std::make_unique<StoreLayout>(dims, brick_bits);
  h.indexer_ = std::make_unique<BrickIndexer>(*h.layout_);
  h.fields_ = fields;
  // Not zeroed here: the build writes every entry of every brick, on all threads.
  const auto n = static_cast<size_t>(h.layout_->brick_count() * h.layout_->brick_nodes());
  h.values_ = std::make_unique_for_overwrite<float[]>(n);
  h.bounds_ = std::make_unique_for_overwrite<uint64_t[]>(n);
  if (fields.surplus) h.surplus_ = std::make_unique_for_overwrite<uint16_t[]>(n);
  if (fields.exact) h.exact_ = std::make_unique_for_overwrite<uint32_t[]>(n);
  if (fields.paper) h.paper_ = std::make_unique_for_overwrite<uint32_t[]>(n);
  if (fields.weights) h.weights_ = std::make_unique_for_overwrite<uint64_t[]>(n);
  // Every page is written, a brick at a time by the tiles: faulted in first, on all threads
  // (docs/METHOD.md, "Fresh memory").
  auto prefault = [n](auto& array) {
    if (array) detail::prefault_in_parallel(array.get(), n * sizeof(array[0]));
  };
  prefault(h.values_), prefault(h.bounds_), prefault(h.surplus_), prefault(h.exact_), prefault(h.paper_),
      prefault(h.weights_);
  return h;
}

namespace {

// The brick size build() takes: BRICK_BITS, or for kMemoryBrickBits the one the store layout
// chooses for these dimensions.
int resolved_brick_bits(const std::array<int64_t, 3>& dims, int brick_bits) {
  return brick_bits == Hierarchy::kMemoryBrickBits ? StoreLayout::memory_brick_bits(dims) : brick_bits;
}

// A slot's bytes over the arrays allocate() makes for these fields.
int64_t slot_bytes(const RecordFields& fields) {
  return static_cast<int64_t>(sizeof(float) + sizeof(uint64_t) + (fields.surplus ? sizeof(uint16_t) : 0) +
                              (fields.exact ? sizeof(uint32_t) : 0) + (fields.paper ? sizeof(uint32_t) : 0) +
                              (fields.weights ? sizeof(uint64_t) : 0));
}

}  // namespace

int64_t Hierarchy::memory_bytes() const {
  return layout_->brick_count() * layout_->brick_nodes() * slot_bytes(fields_);
}

int64_t Hierarchy::memory_bytes(const std::array<int64_t, 3>& dims, const RecordFields& fields, int brick_bits) {
  validate_dims(dims);
  const StoreLayout layout(dims, resolved_brick_bits(dims, brick_bits));
  return layout.brick_count() * layout.brick_nodes() * slot_bytes(fields);
}

namespace {

// The banded build's sink for a hierarchy in memory: each brick straight into its place.
struct MemorySink {
  Hierarchy& h;
  int process(int band, const Box3& b, const BandTile& tile) {
    const int64_t index = h.layout().brick_index(band, b);
    const int64_t t = h.layout().brick_width();
    fill_brick(tile, {b[0] * t, b[1] * t, b[2] * t}, h.brick(index), h.values(index));
    return 0;
  }
  void commit(int, const Box3&, int&&) {}
  void hold(int, const Box3&, int&&) {}
  void release() {}
};

}  // namespace

Hierarchy Hierarchy::build(const Volume& volume, const RecordFields& fields, int brick_bits,
                           const ProgressCallback& progress) {
  validate_volume(volume);
  const auto start = std::chrono::steady_clock::now();
  Hierarchy h = allocate(volume.dims, resolved_brick_bits(volume.dims, brick_bits), fields);
  h.set_geometry(volume.origin, volume.spacing);
  const ReadBox read = [&](const Box3& lo, const Box3& size, float* out) {
    for (int64_t z = 0; z < size[2]; ++z)
      for (int64_t y = 0; y < size[1]; ++y) {
        const float* row = volume.data() + volume.index(lo[0], lo[1] + y, lo[2] + z);
        std::copy(row, row + size[0], out + (z * size[1] + y) * size[0]);
      }
  };
  BandedBuildOptions options;
  options.memory_bytes = uint64_t{256} << 20;  // tiles in flight: the hierarchy itself is already in memory
  options.progress = progress;
  options.topology = fields.topology();  // mode none reads no interval nor weight: none computed
  options.weights = fields.weights;      // only simplify reads them
  MemorySink sink{h};
  const BandedBuildStats built = build_bands(h.layout(), read, sink, 0, options);
  for (int t = 0; t < 3; ++t) {
    h.stats_.critical_paper[t] = built.critical[0][t];
    h.stats_.critical_exact[t] = built.critical[1][t];
  }
  h.stats_.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return h;
}

}  // namespace isotope
