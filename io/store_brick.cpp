#include "io/store_brick.h"

#include <algorithm>

namespace isotope {
namespace {

}  // namespace

int64_t halo_width(const StoreLayout& layout) { return layout.brick_width() + 4; }

int64_t halo_index(const StoreLayout& layout, const Box3& origin, const Box3& g) {
  const int64_t w = halo_width(layout);
  return ((g[2] - origin[2] + 2) * w + (g[1] - origin[1] + 2)) * w + (g[0] - origin[0] + 2);
}

BandTile tile_for_brick(const StoreLayout& layout, int j, const Box3& b, BandTile::Buffers buffers) {
  const Band& band = layout.band(j);
  const int64_t t = layout.brick_width();
  const Box3 lo{b[0] * t, b[1] * t, b[2] * t};
  const Box3 hi{std::min(lo[0] + t, band.nodes[0]), std::min(lo[1] + t, band.nodes[1]),
                std::min(lo[2] + t, band.nodes[2])};
  return BandTile(layout, j, lo, hi, std::move(buffers));
}

BrickContents contents_of(const BandTile& tile, const Box3& origin, float error_fold) {
  const StoreLayout& layout = tile.layout();
  const Band& band = layout.band(tile.band());
  const bool records = tile.band() < layout.lattice().k;  // the corners have none: all absent
  BrickContents b;
  b.values.reserve(static_cast<size_t>(layout.brick_nodes()));
  b.records.reserve(static_cast<size_t>(layout.brick_records()));
  // In Morton order, so each array is written once, front to back (a paged extraction decodes
  // bricks all the time; clearing them first cost as much as filling them).
  for (uint32_t m = 0; m < static_cast<uint32_t>(layout.brick_nodes()); ++m) {
    const Box3 g{origin[0] + compact_bits_3(m), origin[1] + compact_bits_3(m >> 1), origin[2] + compact_bits_3(m >> 2)};
    const bool in_grid = g[0] < band.nodes[0] && g[1] < band.nodes[1] && g[2] < band.nodes[2];
    b.values.push_back(in_grid ? tile.node_value(g) : 0.0f);
    if ((m & 7) == 0) continue;
    if (!in_grid || !records) {
      b.records.push_back(kAbsentRecord);
      continue;
    }
    Record r = tile.node_record(g);
    if (error_fold != 0) {
      r.bounds.error_bound = round_up(static_cast<double>(r.bounds.error_bound) + error_fold);
      r.bounds.error_surplus = round_up(static_cast<double>(r.bounds.error_surplus) + error_fold);
    }
    b.records.push_back(r);
  }
  return b;
}

std::vector<float> halo_values_of(const BandTile& tile, const Box3& origin) {
  const StoreLayout& layout = tile.layout();
  const int64_t w = halo_width(layout);
  std::vector<float> halo(static_cast<size_t>(w * w * w), 0.0f);
  // The brick's box with its halo, cut to the window a tile of this brick alone would have:
  // what the reader's tile_for_brick + fill_from_halo reads back, whatever this tile's size.
  const Box3& nodes = layout.band(0).nodes;
  const int64_t t = layout.brick_width();
  const auto [lo, hi] = BandTile::window_of(layout, 0, origin,
                                            {std::min(origin[0] + t, nodes[0]), std::min(origin[1] + t, nodes[1]),
                                             std::min(origin[2] + t, nodes[2])});
  for (int64_t z = lo[2]; z <= hi[2]; ++z)
    for (int64_t y = lo[1]; y <= hi[1]; ++y)
      for (int64_t x = lo[0]; x <= hi[0]; ++x)
        halo[static_cast<size_t>(halo_index(layout, origin, {x, y, z}))] = tile.node_value({x, y, z});
  return halo;
}

void fill_from_halo(BandTile& tile, const std::vector<float>& halo) {
  const Box3 lo = tile.window_lo(), hi = tile.window_hi(), size = tile.window_size();
  auto& v = tile.values();
  for (int64_t z = lo[2]; z <= hi[2]; ++z)
    for (int64_t y = lo[1]; y <= hi[1]; ++y)
      for (int64_t x = lo[0]; x <= hi[0]; ++x)
        v[static_cast<size_t>(((z - lo[2]) * size[1] + (y - lo[1])) * size[0] + (x - lo[0]))] =
            halo[static_cast<size_t>(halo_index(tile.layout(), tile.core_lo(), {x, y, z}))];
}

}  // namespace isotope
