#pragma once
// Extraction at eps = 0. No error is below 0, so no tetrahedron stops above the finest level
// whatever the mode, indicator or focus: the mesh is marching tetrahedra over every finest cell
// the isosurface cuts (docs/DESIGN.md, invariant 2). Rather than walk the bisection tree down to each
// leaf, the cells are marched block by block: the range record of a block's cube diamond culls
// it when the isovalue misses it, then the range of the block's own nodes (docs/METHOD.md). A
// source without records (a plain array: engine/volume_source.h) is culled by the block's own
// nodes alone, which marches the same blocks: the record's range holds every node of the block.
#include <algorithm>
#include <array>
#include <atomic>
#include <cstdint>
#include <vector>

#include "engine/extract/block_march.h"
#include "engine/extract/extract.h"
#include "engine/extract/slab_march.h"
#include "engine/extract/traversal.h"
#include "engine/extract/traversal_source.h"

namespace isotope {

// Whether extract_finest can run on this lattice: a block is the cube of a cube diamond.
inline bool finest_extract_applies(const Lattice& lattice) { return lattice.k >= 1; }

// Whether min <= iso < max over the nodes of a block held as march_block takes them.
inline bool cut_by(const float* f, int64_t stride, const std::array<int64_t, 3>& cells, float iso) {
  bool below = false, above = false;
  for (int64_t z = 0; z <= cells[2]; ++z)
    for (int64_t y = 0; y <= cells[1]; ++y) {
      const float* row = f + (z * stride + y) * stride;
      for (int64_t x = 0; x <= cells[0]; ++x) {
        below |= row[x] <= iso;
        above |= row[x] > iso;
      }
    }
  return below && above;
}

// Blocks are cubes of 8 cells a side (4 or 2 on lattices of side 5 or 3), whose centres are the
// cube diamonds of scale 2 (1 or 0): their records hold the range of every node of the closed
// cube, and more. The mesh is the same bit for bit on any number of threads, paged or not.
template <ValueSource Source>
Mesh extract_finest(const Source& source, const traversal::SplitRule& rule, ExtractStats* stats) {
  const Lattice& lattice = source.lattice();
  const std::array<int64_t, 3>& dims = source.data_dims();
  const int64_t side = int64_t{2} << std::min(2, lattice.k - 1);  // cells per block edge
  const int64_t stride = side + 1;
  SlabPlan plan;
  plan.cell_layers = dims[2] - 1;
  plan.slab_layers = side;
  plan.side = lattice.side;  // the traversal's edge keys, hence its quadrilateral splits
  plan.iso = rule.options().iso;
  plan.origin = source.origin();
  plan.spacing = source.spacing();
  std::atomic<int64_t> blocks{0}, cells{0};
  Mesh mesh = march_in_slabs(plan, [&](int64_t z0, int64_t z1, MeshBuilder& builder) {
    throw_if_cancelled(rule.options());
    auto reader = source.reader();
    std::vector<float> f(static_cast<size_t>(stride * stride * stride));
    EdgeMemo memo(side);
    int64_t seen = 0, marched = 0;
    for (int64_t y0 = 0; y0 + 1 < dims[1]; y0 += side)
      for (int64_t x0 = 0; x0 + 1 < dims[0]; x0 += side) {
        ++seen;
        const Coord centre{x0 + side / 2, y0 + side / 2, z0 + side / 2};
        if constexpr (RecordReader<decltype(reader)>)
          if (!rule.in_range(
                  reader.bounds(reader.locate(traversal::pack(centre)), RecordFields{false, false, false, false})))
            continue;
        const std::array<int64_t, 3> n{std::min(side, dims[0] - 1 - x0), std::min(side, dims[1] - 1 - y0), z1 - z0};
        const Coord lo{x0, y0, z0};
        bool read = false;
        if constexpr (BlockReader<decltype(reader)>)
          read = reader.block_values(lo, n, f.data(), stride);  // a source that holds blocks together
        if (!read)
          for (int64_t z = 0; z <= n[2]; ++z)
            for (int64_t y = 0; y <= n[1]; ++y)
              for (int64_t x = 0; x <= n[0]; ++x)
                f[static_cast<size_t>((z * stride + y) * stride + x)] = reader.value({x0 + x, y0 + y, z0 + z}, 0);
        // The record's range is saturated over the diamonds below, which reach into the
        // neighbouring blocks: the block's own range culls most of what it lets through.
        if (!cut_by(f.data(), stride, n, plan.iso)) continue;
        march_block(f.data(), stride, {x0, y0, z0}, n, plan.iso, memo, builder);
        marched += n[0] * n[1] * n[2];
      }
    blocks += seen;
    cells += marched;
  });
  if (stats) {
    stats->tets_visited = 6 * (blocks + cells);  // the six tetrahedra of each block's cube, and of each cell
    stats->tets_emitted = 6 * cells;
  }
  return mesh;
}

}  // namespace isotope
