#pragma once
// Extraction at eps = 0. No error is below 0, so no tetrahedron stops above the finest level
// whatever the mode, indicator or focus: the mesh is marching tetrahedra over every finest cell
// the isosurface cuts (docs/DESIGN.md, invariant 2). Rather than walk the bisection tree down to each
// leaf, the cells are marched block by block: the range record of a block's cube diamond culls
// it when the isovalue misses it, then the range of the block's own nodes (docs/METHOD.md). A
// source without records (a plain array: ArraySource) is culled by the block's own
// nodes alone, which marches the same blocks: the record's range holds every node of the block.
#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cstdint>
#include <functional>
#include <limits>
#include <utility>
#include <vector>

#include "engine/core/parallel.h"
#include "engine/extract/block_march.h"
#include "engine/extract/extract_drivers.h"
#include "engine/extract/process_group.h"
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

// The tetrahedra the finest extraction looked at and emitted, from its counts: the six of each
// block's cube, and of each cell.
inline void count_finest(int64_t blocks, int64_t cells, ExtractStats* stats) {
  if (!stats) return;
  stats->tets_visited = 6 * (blocks + cells);
  stats->tets_emitted = 6 * cells;
}

// How far in z one process's finest march has asked its source for the slabs ahead, shared by
// its slabs. Each slab claims the slabs of its window beyond the furthest one claimed so far, so
// that every range record is read once to ask and once to march, whatever the window. A slab left
// below that mark unclaimed is one a slab after it claimed past first; slabs are handed out in
// increasing order (parallel_for_in_order), so such a slab is being marched already, where a hint
// would come too late. No claim reaches past the last slab of the process's share (among several
// processes): the slabs after it are another process's, and asking for them would read their
// range records and hint bricks this process never reads.
class SlabClaims {
 public:
  // The slabs [first, last) after `slab`, up to `slab + ahead` and the process's last, beyond the
  // furthest claimed so far (empty when first >= last).
  std::pair<int64_t, int64_t> claim(int64_t slab, int64_t ahead) {
    const int64_t through = std::min(slab + ahead, last_);
    int64_t before = furthest_.load(std::memory_order_relaxed);
    while (before < through && !furthest_.compare_exchange_weak(before, through, std::memory_order_relaxed)) {
    }
    return {std::max(before, slab) + 1, std::max(before, through) + 1};
  }
  // The process marches no slab after `last_slab` (inclusive). Set before the march starts its
  // threads: claim() reads it unsynchronised, and starting the threads publishes it.
  void end_at(int64_t last_slab) { last_ = last_slab; }

 private:
  std::atomic<int64_t> furthest_{-1};                   // the furthest slab claimed
  int64_t last_ = std::numeric_limits<int64_t>::max();  // the last slab the process marches
};

// The cost of slabs [first, last) of `plan` into OUT, for sharing them among processes
// (ProcessGroup::share_of): from the records of the cube diamonds of scale 2 (the blocks' own,
// cubes of 8 cells a side, in band 2: 1/64 of the data; a slab is one layer of them), the cells of
// the cubes the isovalue may cut, once for each layer of cells the slab holds. Coarser cubes
// (scale 3 or 4, 1/512 or 1/4096 of the data) read less but left the largest of 4 ranks 1.46x the
// mean on embryo, against 1.22x (docs/DISTRIBUTED.md). A source without records, or a cube whose
// centre lies beyond the data: counted as cut.
template <ValueSource Source>
void slab_costs(const Source& source, const traversal::SplitRule& rule, const SlabPlan& plan, size_t first, size_t last,
                double* out) {
  const std::array<int64_t, 3>& dims = source.data_dims();
  const int64_t cube = plan.slab_layers;
  parallel_for(static_cast<int64_t>(first), static_cast<int64_t>(last), [&](int64_t l) {
    auto reader = source.reader();
    double cells = 0;
    for (int64_t y0 = 0; y0 + 1 < dims[1]; y0 += cube)
      for (int64_t x0 = 0; x0 + 1 < dims[0]; x0 += cube) {
        const Coord centre{x0 + cube / 2, y0 + cube / 2, l * cube + cube / 2};
        if constexpr (RecordReader<decltype(reader)>)
          if (centre[0] < dims[0] && centre[1] < dims[1] && centre[2] < dims[2] &&
              !rule.in_range(
                  reader.bounds(reader.locate(traversal::pack(centre)), RecordFields{false, false, false, false})))
            continue;
        cells += static_cast<double>(std::min(cube, dims[0] - 1 - x0) * std::min(cube, dims[1] - 1 - y0));
      }
    const int64_t cell_layers = std::min(cube, plan.cell_layers - l * cube);
    out[static_cast<size_t>(l) - first] = cells * static_cast<double>(cell_layers);
  });
}

// This process marches its share of `plan`'s slabs (SHARE: all of them alone): the mesh on rank 0
// (or, with keep_shares, each rank its own share's; alone, this process's), the counts of every
// rank's, and each rank's load. `bytes_read`: what this process read, asked after its march.
// `on_failure`: as march_in_slabs's.
inline Mesh march_finest_share(const SlabPlan& plan, const MarchSlab& march, const ProcessGroup& group,
                               const ProcessGroup::Share& share, bool keep_shares, std::atomic<int64_t>& blocks,
                               std::atomic<int64_t>& cells, const std::function<uint64_t()>& bytes_read,
                               ExtractStats* stats, const std::function<void()>& on_failure = {}) {
  RankLoad load;
  Mesh mesh = group.march_slabs(plan, march, share, &load.seconds, keep_shares, on_failure);
  for (size_t s = share.first; s < share.last && s < share.costs.size(); ++s) load.cost += share.costs[s];
  load.items = static_cast<int64_t>(share.last - share.first);
  load.work = cells;
  if (bytes_read) load.bytes_read = bytes_read();
  std::vector<RankLoad> loads = group.loads(load);
  const int64_t all_cells = group.sum(cells), all_blocks = group.sum(blocks);
  count_finest(all_blocks, all_cells, stats);
  if (stats) stats->ranks = std::move(loads);
  return mesh;
}

// Blocks are cubes of 8 cells a side (4 or 2 on lattices of side 5 or 3), whose centres are the
// cube diamonds of scale 2 (1 or 0): their records hold the range of every node of the closed
// cube, and more. Slabs are one layer of blocks.
inline SlabPlan finest_plan(const Lattice& lattice, const std::array<int64_t, 3>& dims, float iso,
                            const std::array<double, 3>& origin, const std::array<double, 3>& spacing) {
  SlabPlan plan;
  plan.cell_layers = dims[2] - 1;
  plan.slab_layers = int64_t{2} << std::min(2, lattice.k - 1);  // cells per block edge
  plan.side = lattice.side;  // the traversal's edge keys, hence its quadrilateral splits
  plan.layer_nodes = {dims[0], dims[1]};
  plan.iso = iso;
  plan.origin = origin;
  plan.spacing = spacing;
  return plan;
}

// How many slabs beyond its own the finest march asks a store for: four beyond those the threads
// march at once (on two threads, five; with the threads left out, eight measured as four).
inline int64_t finest_slabs_ahead() { return 3 + thread_count(); }

// The cells per axis of the block of PLAN whose lowest corner is (x0, y0, z0), `layers` cell layers
// deep: as many as the plan's blocks have, fewer at the volume's far faces.
inline std::array<int64_t, 3> finest_block_cells(const SlabPlan& plan, const std::array<int64_t, 3>& dims, int64_t x0,
                                                 int64_t y0, int64_t layers) {
  const int64_t side = plan.slab_layers;
  return {std::min(side, dims[0] - 1 - x0), std::min(side, dims[1] - 1 - y0), layers};
}

// Whether the isovalue may cut the block of `side` cells a side at (x0, y0, zb): its cube
// diamond's range record. A source without records: always.
template <class Reader>
bool finest_block_in_range(Reader& reader, const traversal::SplitRule& rule, int64_t side, int64_t x0, int64_t y0,
                           int64_t zb) {
  if constexpr (RecordReader<Reader>) {
    const Coord centre{x0 + side / 2, y0 + side / 2, zb + side / 2};
    return rule.in_range(
        reader.bounds(reader.locate(traversal::pack(centre)), RecordFields{false, false, false, false}));
  } else {
    return true;
  }
}

// The blocks of cell layers [z0, z1) (one slab of PLAN) that the isovalue cuts, marched, their
// values read through READER (global coordinates). Counts the blocks looked at and the cells marched.
template <class Reader>
void march_finest_layers(Reader& reader, const traversal::SplitRule& rule, const SlabPlan& plan,
                         const std::array<int64_t, 3>& dims, int64_t z0, int64_t z1, MeshBuilder& builder,
                         std::atomic<int64_t>& blocks, std::atomic<int64_t>& cells) {
  const int64_t side = plan.slab_layers;
  const int64_t stride = side + 1;
  std::vector<float> f(static_cast<size_t>(stride * stride * stride));
  // A slab is one layer of blocks, marched by a builder of its own (march_in_slabs): the memo
  // holds every vertex its blocks share, a row of blocks at a time.
  LentEdgeMemo lent;
  EdgeMemo& memo = *lent;
  memo.reshape(side, dims[0]);
  memo.start_slab();
  int64_t seen = 0, marched = 0;
  for (int64_t y0 = 0; y0 + 1 < dims[1]; y0 += side) {
    memo.start_row();
    for (int64_t x0 = 0; x0 + 1 < dims[0]; x0 += side) {
      ++seen;
      if (!finest_block_in_range(reader, rule, side, x0, y0, z0)) continue;
      const std::array<int64_t, 3> n = finest_block_cells(plan, dims, x0, y0, z1 - z0);
      const Coord lo{x0, y0, z0};
      constexpr bool kCutsInPlace = requires { reader.block_cut(lo, n, plan.iso); };
      if constexpr (kCutsInPlace)
        if (!reader.block_cut(lo, n, plan.iso)) continue;
      bool read = false;
      if constexpr (BlockReader<Reader>)
        read = reader.block_values(lo, n, f.data(), stride);  // a source that holds blocks together
      if (!read)
        for (int64_t z = 0; z <= n[2]; ++z)
          for (int64_t y = 0; y <= n[1]; ++y)
            for (int64_t x = 0; x <= n[0]; ++x)
              f[static_cast<size_t>((z * stride + y) * stride + x)] = reader.value({x0 + x, y0 + y, z0 + z}, 0);
      // The record's range is saturated over the diamonds below, which reach into the
      // neighbouring blocks: the block's own range culls most of what it lets through.
      if (!kCutsInPlace && !cut_by(f.data(), stride, n, plan.iso)) continue;
      march_block(f.data(), stride, {x0, y0, z0}, n, plan.iso, memo, builder);
      marched += n[0] * n[1] * n[2];
    }
  }
  blocks += seen;
  cells += marched;
}

// One slab of the finest march, [z0, z1) (z0 a multiple of the slab's layers, as slab_range
// makes it). Over a source that reads its bricks from a file on demand (a store), once a read has
// waited for the disk, the slab first asks for the bricks of the blocks the isovalue may cut in
// the slabs it claims of its window ahead (CLAIMS), so that their reads are in flight while it is
// marched instead of each waiting in turn for the disk when its block is reached (docs/METHOD.md,
// "Out of core"); the source asks the kernel once a brick. A slab that began before any read
// waited claims once it is marched. Any other source: march_finest_layers alone.
template <class Reader>
void march_finest_slab(Reader& reader, const traversal::SplitRule& rule, const SlabPlan& plan,
                       const std::array<int64_t, 3>& dims, int64_t z0, int64_t z1, MeshBuilder& builder,
                       std::atomic<int64_t>& blocks, std::atomic<int64_t>& cells, SlabClaims& claims) {
  constexpr bool kAsks = requires(const Coord& lo, const std::array<int64_t, 3>& n) {
    reader.hints_pay();
    reader.prefetch_block(lo, n);
  };
  if constexpr (!kAsks) {
    march_finest_layers(reader, rule, plan, dims, z0, z1, builder, blocks, cells);
  } else {
    const int64_t side = plan.slab_layers;
    auto ask_ahead = [&] {
      const auto [first, last] = claims.claim(z0 / side, finest_slabs_ahead());
      for (int64_t zb = first * side; zb < std::min(last * side, plan.cell_layers); zb += side)
        for (int64_t y0 = 0; y0 + 1 < dims[1]; y0 += side)
          for (int64_t x0 = 0; x0 + 1 < dims[0]; x0 += side)
            if (finest_block_in_range(reader, rule, side, x0, y0, zb))
              reader.prefetch_block({x0, y0, zb},
                                    finest_block_cells(plan, dims, x0, y0, std::min(side, plan.cell_layers - zb)));
    };
    const bool hints_paid = reader.hints_pay();
    if (hints_paid) ask_ahead();
    march_finest_layers(reader, rule, plan, dims, z0, z1, builder, blocks, cells);
    if (!hints_paid && reader.hints_pay()) ask_ahead();
  }
}

// The mesh is the same bit for bit on any number of threads, paged or not, and on any number of
// processes (the slabs shared by their cost, estimated from the source's records: slab_costs).
template <ValueSource Source>
Mesh extract_finest(const Source& source, const traversal::SplitRule& rule, ExtractStats* stats) {
  const std::array<int64_t, 3>& dims = source.data_dims();
  const SlabPlan plan = finest_plan(source.lattice(), dims, rule.options().iso, source.origin(), source.spacing());
  const ProcessGroup group(rule.options().distribution);
  const ProcessGroup::Share share =
      group.share_of(static_cast<size_t>(slab_count(plan)),
                     [&](size_t first, size_t last, double* out) { slab_costs(source, rule, plan, first, last, out); });
  std::atomic<int64_t> blocks{0}, cells{0};
  SlabClaims claims;
  claims.end_at(static_cast<int64_t>(share.last) - 1);
  const MarchSlab march = [&](int64_t z0, int64_t z1, MeshBuilder& builder) {
    throw_if_cancelled(rule.options());
    auto reader = source.reader();
    march_finest_slab(reader, rule, plan, dims, z0, z1, builder, blocks, cells, claims);
  };
  std::function<uint64_t()> bytes_read;
  if constexpr (requires { source.bytes_read(); }) bytes_read = [&] { return source.bytes_read(); };
  return march_finest_share(plan, march, group, share, rule.options().keep_shares, blocks, cells, bytes_read, stats);
}

}  // namespace isotope
