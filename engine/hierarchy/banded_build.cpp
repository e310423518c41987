#include "engine/hierarchy/banded_build.h"

#include <algorithm>
#include <cassert>
#include <tuple>

#include "engine/core/lanes.h"

namespace isotope {

std::vector<Box3> in_morton_order(const Box3& count) {
  std::vector<std::pair<uint64_t, Box3>> order;
  for (int64_t z = 0; z < count[2]; ++z)
    for (int64_t y = 0; y < count[1]; ++y)
      for (int64_t x = 0; x < count[0]; ++x)
        order.push_back(
            {morton_encode(static_cast<uint64_t>(x), static_cast<uint64_t>(y), static_cast<uint64_t>(z)), {x, y, z}});
  std::sort(order.begin(), order.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
  std::vector<Box3> out;
  out.reserve(order.size());
  for (const auto& [key, b] : order) out.push_back(b);
  return out;
}

std::vector<double> tile_costs(const StoreLayout& layout, const Band& band, int64_t c) {
  const int64_t side = c * layout.brick_width();
  std::vector<double> costs;
  for (const Box3& t : in_morton_order(tile_grid(band, c))) {
    double nodes = 1;
    for (int a = 0; a < 3; ++a) nodes *= static_cast<double>(std::min(side, band.nodes[a] - t[a] * side));
    costs.push_back(nodes);
  }
  return costs;
}

int64_t tile_bytes(const StoreLayout& layout, int64_t c, int64_t brick_bytes, bool fused) {
  const int64_t window = sizeof(float) + 2 * sizeof(Record);  // values, records, children a node
  const int64_t side = c * layout.brick_width();
  if (!fused) {
    const int64_t w = side + 4;
    return w * w * w * window + c * c * c * brick_bytes;
  }
  // The widened tile of band j, the tile of band j+1 (one node more at the grid's far faces),
  // and the box between them; band j+1's bricks, an eighth as many.
  const int64_t w = side + kFuseBelow + kFuseAbove + 4, u = side / 2 + 1 + 4;
  return w * w * w * window + u * u * u * (window + static_cast<int64_t>(sizeof(float) + sizeof(Record))) +
         c * c * c * brick_bytes * 9 / 8;
}

int64_t tile_bricks_for(const StoreLayout& layout, int64_t sink_brick_bytes, uint64_t memory_bytes, bool fused) {
  // The largest c up to a side of 32 nodes (fused: 64, or 128) that keeps every thread busy within
  // three quarters of the budget, and gives every thread a few tiles of band 0.
  // - A tile whose hand-over is in memory is built from its window alone; one of 32^3 nodes keeps
  //   its records (36^3 of them, 2.2 MB) in cache from build to brick. It computes more of its
  //   halo's records twice (embryo's convert on one thread: 10% more instructions), and still
  //   takes less time: on two threads embryo's convert 0.485 -> 0.444 s, its in-memory build
  //   0.90 -> 0.80 s on one thread, a 512^3 one 3.2 -> 2.6 s on two, against tiles of 64^3.
  // - A fused tile computes a halo of records twice, so larger is better: 64^3, and 128^3 where
  //   band 0 has at least 64 such tiles a thread, so that the last tiles leave no thread idle for
  //   long (at 1024^3 band 0's fused tiles of 64^3 compute 35% more records than their cores hold,
  //   those of 128^3 16%: the convert 40.0 -> 36.1 s on two threads; a 257^3 or 513^3 one is
  //   slower with them).
  const int64_t threads = thread_count();
  const auto budget = static_cast<int64_t>(memory_bytes / 4 * 3);
  int64_t c = std::max<int64_t>(1, int64_t{fused ? 64 : 32} >> layout.brick_bits());
  if (fused && static_cast<int64_t>(tile_count(layout.band(0), 2 * c)) >= 64 * threads) c *= 2;
  while (c > 1 && (budget / tile_bytes(layout, c, sink_brick_bytes, fused) < threads ||
                   static_cast<int64_t>(tile_count(layout.band(0), c)) < 4 * threads))
    c /= 2;
  return c;
}

int64_t fused_tile_bricks_for(const StoreLayout& layout, int64_t sink_brick_bytes, uint64_t memory_bytes) {
  const int64_t c = tile_bricks_for(layout, sink_brick_bytes, memory_bytes, true);
  return c % 2 == 0 && c * layout.brick_width() >= kFusedSide ? c : 0;
}

int64_t band_tile_bricks(const StoreLayout& layout, const Band& band, int64_t c) {
  const int64_t threads = thread_count();
  if (threads <= 1) return c;
  const double nodes =
      static_cast<double>(band.nodes[0]) * static_cast<double>(band.nodes[1]) * static_cast<double>(band.nodes[2]);
  for (; c > 1; c /= 2) {
    const auto side = static_cast<double>(c * layout.brick_width());
    if (nodes >= kFullTilesAThread * static_cast<double>(threads) * side * side * side) break;
  }
  return c;
}

int64_t stage_tiles_for(const StoreLayout& layout, int band, int64_t c, uint64_t room, bool fused) {
  const Band& b = layout.band(band);
  const Box3 grid = tile_grid(b, c);
  const int64_t most = std::max({grid[0], grid[1], grid[2]});
  const int64_t w = c * layout.brick_width();
  // What the group hands on: band j+1's nodes, or band j+2's when band j+1 is built beside it.
  const int step = fused ? 2 : 1;
  int64_t best = 0;
  for (int64_t s = 2; s / 2 < most; s *= 2) {
    Box3 box, next;
    for (int a = 0; a < 3; ++a) {
      const int64_t side = std::min(s * w, b.nodes[a]);
      box[a] = side + 4 + (fused ? kFuseBelow + kFuseAbove : 0);  // up to two nodes of halo each side
      next[a] = (side >> step) + 1;
    }
    uint64_t bytes = banded_build_internal::StagedBox::bytes(box, band > 0);
    if (band + step <= layout.lattice().k) bytes += 2 * banded_build_internal::StagedNext::bytes(next);
    if (bytes > room) break;
    best = s;
  }
  return best;
}

namespace banded_build_internal {

void StagedBox::frame(const Box3& lo, const Box3& hi, const Box3& grid, bool children) {
  grid_ = grid;
  children_ = children;
  for (int a = 0; a < 3; ++a) {
    lo_[a] = std::min(lo[a], grid[a] - 1);
    size_[a] = std::min(hi[a], grid[a] - 1) - lo_[a] + 1;
    // The cells whose corner node lies in the grid; the others' centres are beyond record_extent
    // and never read.
    assert(!children || lo[a] < grid[a]);
    cell_size_[a] = children ? std::max<int64_t>(0, std::min(hi[a], grid[a]) - lo_[a]) : 0;
  }
  cell_lo_ = lo_;
  values_.resize(static_cast<size_t>(size_[0] * size_[1] * size_[2]));
}

uint64_t StagedBox::bytes(const Box3& size, bool children) {
  uint64_t nodes = 1, cells = 1;
  for (int a = 0; a < 3; ++a) {
    nodes *= static_cast<uint64_t>(size[a]);
    cells *= static_cast<uint64_t>(size[a] - 1);
  }
  return nodes * sizeof(float) + (children ? cells * sizeof(Record) : 0);
}

void StagedBox::read_input(const Box3& lo, const Box3& hi, const Box3& dims, const ReadBox& read) {
  frame(lo, hi, dims, false);
  const int64_t plane = size_[0] * size_[1];
  // A plane a call: a box that spans whole rows is one contiguous read a plane; planes on every
  // thread, as the input's reader allows (a tile's own box is read by its thread, at once).
  const int64_t chunks = thread_count() > 1 && plane * size_[2] > (int64_t{1} << 20) ? size_[2] : 1;
  parallel_for(int64_t{0}, chunks, [&](int64_t i) {
    const int64_t z0 = size_[2] * i / chunks, z1 = size_[2] * (i + 1) / chunks;
    read({lo_[0], lo_[1], lo_[2] + z0}, {size_[0], size_[1], z1 - z0}, values_.data() + z0 * plane);
  });
}

void StagedBox::read_handover(const Box3& lo, const Box3& hi, const BandHandover& in) {
  frame(lo, hi, in.nodes(), true);
  records_.resize(static_cast<size_t>(cell_size_[0] * cell_size_[1] * cell_size_[2]));
  // Slabs of planes cut at the hand-over's blocks, on every thread.
  const int64_t first = lo_[2] / kHandoverBlock, last = (lo_[2] + size_[2] - 1) / kHandoverBlock;
  const bool parallel = thread_count() > 1 && size_[0] * size_[1] * size_[2] > (int64_t{1} << 18);
  parallel_for(first, parallel ? last + 1 : first + 1, [&](int64_t i) {
    const int64_t z0 = parallel ? std::max(lo_[2], i * kHandoverBlock) : lo_[2];
    const int64_t z1 = parallel ? std::min(lo_[2] + size_[2], (i + 1) * kHandoverBlock) : lo_[2] + size_[2];
    in.read_values({lo_[0], lo_[1], z0}, {lo_[0] + size_[0], lo_[1] + size_[1], z1},
                   values_.data() + (z0 - lo_[2]) * size_[0] * size_[1], size_[0], size_[0] * size_[1]);
    const int64_t c1 = std::min(z1, cell_lo_[2] + cell_size_[2]);
    if (c1 <= z0 || cell_size_[0] == 0 || cell_size_[1] == 0) return;
    in.read_children({cell_lo_[0], cell_lo_[1], z0}, {cell_lo_[0] + cell_size_[0], cell_lo_[1] + cell_size_[1], c1},
                     records_.data() + (z0 - cell_lo_[2]) * cell_size_[0] * cell_size_[1], cell_size_[0],
                     cell_size_[0] * cell_size_[1]);
  });
}

void StagedBox::take_next(const BandTile& from, const BandTile& to) {
  frame(to.window_lo(), to.window_hi(), to.layout().band(to.band()).nodes, true);
  records_.resize(values_.size());
  // The cells (one fewer than the nodes along each axis, but at the grid's far faces) are the
  // first entries of a row; their rows packed as fill() reads them.
  for (int64_t z = 0; z < size_[2]; ++z)
    for (int64_t y = 0; y < size_[1]; ++y) {
      const bool cells = z < cell_size_[2] && y < cell_size_[1];
      from.next_row(lo_[0], lo_[0] + size_[0], lo_[1] + y, lo_[2] + z, values_.data() + (z * size_[1] + y) * size_[0],
                    records_.data() + (cells ? (z * cell_size_[1] + y) * cell_size_[0] : 0), cells ? cell_size_[0] : 0);
    }
}

void StagedBox::fill(BandTile& tile) const {
  const Box3 lo = tile.window_lo(), size = tile.window_size();
  for (int a = 0; a < 3; ++a)
    assert(std::min(lo[a], grid_[a] - 1) >= lo_[a] && std::min(tile.window_hi()[a], grid_[a] - 1) < lo_[a] + size_[a] &&
           "the box holds the tile's window");
  auto& v = tile.values();
  // Along x, the nodes up to the grid's last, then that last one repeated.
  const int64_t inside = std::clamp<int64_t>(grid_[0] - lo[0], 0, size[0]);
  for (int64_t z = 0; z < size[2]; ++z)
    for (int64_t y = 0; y < size[1]; ++y) {
      const int64_t bz = std::min(lo[2] + z, grid_[2] - 1) - lo_[2], by = std::min(lo[1] + y, grid_[1] - 1) - lo_[1];
      const float* row = values_.data() + (bz * size_[1] + by) * size_[0];
      float* dst = v.data() + (z * size[1] + y) * size[0];
      std::copy_n(row + (lo[0] - lo_[0]), inside, dst);
      if (inside < size[0]) std::fill(dst + inside, dst + size[0], row[grid_[0] - 1 - lo_[0]]);
    }
  if (!children_) return;
  const Box3 cells{size[0] - 1, size[1] - 1, size[2] - 1};
  const int64_t cx = std::min(cells[0], grid_[0] - lo[0]);
  if (cx <= 0) return;
  auto& c = tile.children();
  for (int64_t z = 0; z < cells[2] && lo[2] + z < grid_[2]; ++z)
    for (int64_t y = 0; y < cells[1] && lo[1] + y < grid_[1]; ++y) {
      const Record* src = records_.data() +
                          ((lo[2] + z - cell_lo_[2]) * cell_size_[1] + (lo[1] + y - cell_lo_[1])) * cell_size_[0] +
                          (lo[0] - cell_lo_[0]);
      std::copy_n(src, cx, c.data() + (z * cells[1] + y) * cells[0]);
    }
}

void fill_from_handover(BandTile& tile, const BandHandover& in) {
  const Box3& n = in.nodes();
  const Box3 lo = tile.window_lo(), size = tile.window_size();
  // The window's nodes in the grid, read in place; those beyond its far faces repeat its last.
  Box3 inside;
  for (int a = 0; a < 3; ++a) {
    assert(lo[a] < n[a] && "a tile's window starts in its band's grid");
    inside[a] = std::min(size[a], n[a] - lo[a]);
  }
  auto& v = tile.values();
  const int64_t plane = size[0] * size[1];
  in.read_values(lo, {lo[0] + inside[0], lo[1] + inside[1], lo[2] + inside[2]}, v.data(), size[0], plane);
  for (int64_t z = 0; z < size[2]; ++z) {
    float* p = v.data() + z * plane;
    if (z >= inside[2]) {
      std::copy_n(v.data() + (inside[2] - 1) * plane, plane, p);
      continue;
    }
    for (int64_t y = 0; y < size[1]; ++y) {
      float* row = p + y * size[0];
      if (y >= inside[1])
        std::copy_n(p + (inside[1] - 1) * size[0], size[0], row);
      else
        std::fill(row + inside[0], row + size[0], row[inside[0] - 1]);
    }
  }
  // Cells of the window whose corner node lies in the grid; the others' centres are beyond
  // record_extent and never read.
  const Box3 cells{size[0] - 1, size[1] - 1, size[2] - 1};
  Box3 hi;
  for (int a = 0; a < 3; ++a) hi[a] = lo[a] + std::min(cells[a], n[a] - lo[a]);
  if (hi[0] <= lo[0]) return;
  in.read_children(lo, hi, tile.children().data(), cells[0], cells[0] * cells[1]);
}

void StagedNext::reset(const Box3& lo, const Box3& hi) {
  lo_ = lo;
  for (int a = 0; a < 3; ++a) size_[a] = std::max<int64_t>(0, hi[a] - lo[a]);
  const auto count = static_cast<size_t>(size_[0] * size_[1] * size_[2]);
  values_.resize(count);
  children_.resize(count);
}

uint64_t StagedNext::bytes(const Box3& size) {
  uint64_t n = 1;
  for (int a = 0; a < 3; ++a) n *= static_cast<uint64_t>(std::max<int64_t>(0, size[a]));
  return n * (sizeof(float) + sizeof(Record));
}

void StagedNext::take(const BandTile& tile) {
  const Box3 lo = tile.next_lo(), hi = tile.next_hi();
  if (lo[0] >= hi[0]) return;
  for (int64_t z = lo[2]; z < hi[2]; ++z)
    for (int64_t y = lo[1]; y < hi[1]; ++y)
      tile.next_row(lo[0], hi[0], y, z, values_.data() + index(lo[0], y, z), children_.data() + index(lo[0], y, z));
}

void StagedNext::write(const std::vector<std::pair<Box3, Box3>>& tile_boxes, BandHandover& next) const {
  // Runs along x of boxes with the same rows (a row of tiles of the group).
  std::vector<std::pair<Box3, Box3>> boxes;
  for (const auto& [lo, hi] : tile_boxes)
    if (lo[0] < hi[0] && lo[1] < hi[1] && lo[2] < hi[2]) boxes.emplace_back(lo, hi);
  std::sort(boxes.begin(), boxes.end(), [](const auto& a, const auto& b) {
    return std::tie(a.first[2], a.first[1], a.first[0]) < std::tie(b.first[2], b.first[1], b.first[0]);
  });
  std::vector<std::pair<Box3, Box3>> runs;
  for (const auto& [lo, hi] : boxes) {
    if (!runs.empty()) {
      auto& [rlo, rhi] = runs.back();
      if (rlo[1] == lo[1] && rlo[2] == lo[2] && rhi[1] == hi[1] && rhi[2] == hi[2] && rhi[0] == lo[0]) {
        rhi[0] = hi[0];
        continue;
      }
    }
    runs.emplace_back(lo, hi);
  }
  // On one thread: writes to one file take its inode's lock, for which a second thread would spin.
  for (const auto& [lo, hi] : runs)
    next.write_box(lo, hi, values_.data() + index(lo[0], lo[1], lo[2]), children_.data() + index(lo[0], lo[1], lo[2]),
                   size_[0], size_[0] * size_[1]);
}

void write_next(const BandTile& tile, BandHandover& next) {
  const Box3 lo = tile.next_lo(), hi = tile.next_hi();
  const int64_t nx = hi[0] - lo[0], ny = hi[1] - lo[1];
  if (nx <= 0 || ny <= 0) return;
  // Slabs of planes cut at the hand-over's blocks: a file writes a block's part of a slab in a
  // call, and a slab of a tile's part stays in cache between its gathering and its writing (16
  // planes of 33 x 33 entries from a fused tile of 128^3: 0.7 MB).
  thread_local std::vector<float> v;
  thread_local std::vector<Record> r;
  const auto slab = static_cast<size_t>(kHandoverBlock * nx * ny);
  if (v.size() < slab) {
    v.resize(slab);
    r.resize(slab);
  }
  for (int64_t z0 = lo[2]; z0 < hi[2];) {
    const int64_t z1 = std::min(hi[2], (z0 / kHandoverBlock + 1) * kHandoverBlock);
    for (int64_t z = z0; z < z1; ++z)
      for (int64_t y = lo[1]; y < hi[1]; ++y) {
        const int64_t at = ((z - z0) * ny + (y - lo[1])) * nx;
        tile.next_row(lo[0], hi[0], y, z, v.data() + at, r.data() + at);
      }
    next.write_box({lo[0], lo[1], z0}, {hi[0], hi[1], z1}, v.data(), r.data(), nx, nx * ny);
    z0 = z1;
  }
}

// The least and greatest of n > 0 values, as std::minmax_element finds them: of equal values
// the first least and the last greatest, which differ in their bits only for -0 and 0. Four
// lanes at a time, the row taken again in that order where either end is a zero.
static std::pair<float, float> row_range(const float* row, int64_t n) {
  float mn = row[0], mx = row[0];
  int64_t i = 0;
#if defined(__SSE2__)
  if (n >= 4) {
    __m128 l = _mm_loadu_ps(row), h = l;
    for (i = 4; i + 4 <= n; i += 4) {
      const __m128 v = _mm_loadu_ps(row + i);
      l = _mm_min_ps(l, v);
      h = _mm_max_ps(h, v);
    }
    mn = least_lane(l);
    mx = greatest_lane(h);
  }
#endif
  for (; i < n; ++i) {
    mn = std::min(mn, row[i]);
    mx = std::max(mx, row[i]);
  }
  if (mn == 0.0f || mx == 0.0f) {
    const auto [first_least, last_greatest] = std::minmax_element(row, row + n);
    return {*first_least, *last_greatest};
  }
  return {mn, mx};
}

void value_range(const BandTile& tile, const StoreLayout& layout, float& lo, float& hi) {
  // Over the nodes the tile counts: a fused tile's widened core reaches into its neighbours'.
  const auto& d = layout.dims();
  const Box3 &c0 = tile.count_lo(), &c1 = tile.count_hi();
  const int64_t x1 = std::min(c1[0], d[0]);
  if (x1 <= c0[0]) return;
  for (int64_t z = c0[2]; z < std::min(c1[2], d[2]); ++z)
    for (int64_t y = c0[1]; y < std::min(c1[1], d[1]); ++y) {
      const float* row = &tile.node_value({c0[0], y, z});
      const auto [mn, mx] = row_range(row, x1 - c0[0]);
      lo = std::min(lo, mn);
      hi = std::max(hi, mx);
    }
}

}  // namespace banded_build_internal
}  // namespace isotope
