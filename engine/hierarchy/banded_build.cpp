#include "engine/hierarchy/banded_build.h"

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

int64_t tile_bytes(const StoreLayout& layout, int64_t c, int64_t brick_bytes) {
  const int64_t w = c * layout.brick_width() + 4;
  return w * w * w * static_cast<int64_t>(sizeof(float) + 2 * sizeof(Record)) + c * c * c * brick_bytes;
}

int64_t tile_bricks_for(const StoreLayout& layout, int64_t sink_brick_bytes, uint64_t memory_bytes) {
  // Larger tiles compute fewer halo records twice and read their input in fewer, longer calls:
  // the largest c (tiles up to 64^3 nodes) that keeps every thread busy within three quarters of
  // the budget, and gives every thread a few tiles of band 0.
  const int64_t threads = thread_count();
  const auto budget = static_cast<int64_t>(memory_bytes / 4 * 3);
  int64_t c = std::max<int64_t>(1, int64_t{64} >> layout.brick_bits());
  while (c > 1 && (budget / tile_bytes(layout, c, sink_brick_bytes) < threads ||
                   static_cast<int64_t>(tile_count(layout.band(0), c)) < 4 * threads))
    c /= 2;
  return c;
}

namespace banded_build_internal {

void fill_from_input(BandTile& tile, const StoreLayout& layout, const ReadBox& read) {
  const auto& dims = layout.dims();
  const Box3 lo = tile.window_lo(), hi = tile.window_hi(), size = tile.window_size();
  Box3 rlo, rsize;
  for (int a = 0; a < 3; ++a) {
    rlo[a] = std::min(lo[a], dims[a] - 1);
    rsize[a] = std::min(hi[a], dims[a] - 1) - rlo[a] + 1;
  }
  thread_local std::vector<float> box;
  box.resize(static_cast<size_t>(rsize[0] * rsize[1] * rsize[2]));
  read(rlo, rsize, box.data());
  auto& v = tile.values();
  for (int64_t z = 0; z < size[2]; ++z)
    for (int64_t y = 0; y < size[1]; ++y) {
      const int64_t bz = std::min(lo[2] + z, dims[2] - 1) - rlo[2], by = std::min(lo[1] + y, dims[1] - 1) - rlo[1];
      const float* row = box.data() + (bz * rsize[1] + by) * rsize[0];
      float* dst = v.data() + (z * size[1] + y) * size[0];
      for (int64_t x = 0; x < size[0]; ++x) dst[x] = row[std::min(lo[0] + x, dims[0] - 1) - rlo[0]];
    }
}

void fill_from_handover(BandTile& tile, const BandHandover& in) {
  const Box3& n = in.nodes();
  const Box3 lo = tile.window_lo(), hi = tile.window_hi(), size = tile.window_size();
  const int64_t x0 = std::min(lo[0], n[0] - 1), count = std::min(hi[0], n[0] - 1) - x0 + 1;
  thread_local std::vector<float> row;
  row.resize(static_cast<size_t>(count));
  auto& v = tile.values();
  for (int64_t z = 0; z < size[2]; ++z)
    for (int64_t y = 0; y < size[1]; ++y) {
      in.read_values(x0, count, std::min(lo[1] + y, n[1] - 1), std::min(lo[2] + z, n[2] - 1), row.data());
      float* dst = v.data() + (z * size[1] + y) * size[0];
      for (int64_t x = 0; x < size[0]; ++x) dst[x] = row[static_cast<size_t>(std::min(lo[0] + x, n[0] - 1) - x0)];
    }
  // Cells of the window whose corner node lies in the grid; the others' centres are beyond
  // record_extent and never read.
  const Box3 cells{size[0] - 1, size[1] - 1, size[2] - 1};
  const int64_t cx = std::min(cells[0], n[0] - lo[0]);
  if (cx <= 0) return;
  auto& c = tile.children();
  for (int64_t z = 0; z < cells[2] && lo[2] + z < n[2]; ++z)
    for (int64_t y = 0; y < cells[1] && lo[1] + y < n[1]; ++y)
      in.read_children(lo[0], cx, lo[1] + y, lo[2] + z, c.data() + (z * cells[1] + y) * cells[0]);
}

void write_next(const BandTile& tile, BandHandover& next) {
  const Box3 lo = tile.next_lo(), hi = tile.next_hi();
  const auto n = static_cast<size_t>(std::max<int64_t>(0, hi[0] - lo[0]));
  if (n == 0) return;
  thread_local std::vector<float> v;
  thread_local std::vector<Record> r;
  v.resize(n);
  r.resize(n);
  for (int64_t z = lo[2]; z < hi[2]; ++z)
    for (int64_t y = lo[1]; y < hi[1]; ++y) {
      for (int64_t x = lo[0]; x < hi[0]; ++x) {
        v[static_cast<size_t>(x - lo[0])] = tile.next_value({x, y, z});
        r[static_cast<size_t>(x - lo[0])] = tile.next_child({x, y, z});
      }
      next.write_row(lo[0], y, z, v.data(), r.data(), static_cast<int64_t>(n));
    }
}

void value_range(const BandTile& tile, const StoreLayout& layout, float& lo, float& hi) {
  const auto& d = layout.dims();
  for (int64_t z = tile.core_lo()[2]; z < std::min(tile.core_hi()[2], d[2]); ++z)
    for (int64_t y = tile.core_lo()[1]; y < std::min(tile.core_hi()[1], d[1]); ++y)
      for (int64_t x = tile.core_lo()[0]; x < std::min(tile.core_hi()[0], d[0]); ++x) {
        const float v = tile.node_value({x, y, z});
        lo = std::min(lo, v);
        hi = std::max(hi, v);
      }
}

}  // namespace banded_build_internal
}  // namespace isotope
