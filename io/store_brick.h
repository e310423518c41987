#pragma once
// Between a band tile (engine/band_tile.h) and what a brick stores (docs/FORMAT.md, "Bricks").
// Bands j >= 1 store their values and records. Band 0 stores only values, with a halo of two
// nodes: its records (7/8 of all) are a function of those values alone (scale-0 vertices have
// leaves for children), so they are rebuilt when the brick is read. That keeps the store near
// the size of the input: the records of band 0 would cost more than the values themselves.
#include <vector>

#include "engine/band_tile.h"
#include "io/store_format.h"

namespace isotope {

// The brick of band `j` at brick coordinates b, as a tile core (G_j nodes).
BandTile tile_for_brick(const StoreLayout& layout, int j, const Box3& b, BandTile::Buffers buffers = {});

// The uniform in-memory form of the brick whose first node is `origin` (G_j units; inside the
// tile's core), values in Morton order and records, from a built tile. `error_fold` is added to
// every finite error of its records (quantized stores).
BrickContents contents_of(const BandTile& tile, const Box3& origin, float error_fold = 0);

// Band 0: the stored values, a (T+4)^3 box from two nodes below the brick, x fastest; nodes
// outside the tile's window (beyond the lattice) are zero.
std::vector<float> halo_values_of(const BandTile& tile, const Box3& origin);
// The inverse: fills the window of a band-0 tile of one brick (tile_for_brick) from its halo values.
void fill_from_halo(BandTile& tile, const std::vector<float>& halo);
int64_t halo_width(const StoreLayout& layout);
// Position of band-0 node g in the halo values of the brick whose first node is `origin`.
int64_t halo_index(const StoreLayout& layout, const Box3& origin, const Box3& g);

}  // namespace isotope
