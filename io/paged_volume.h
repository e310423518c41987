#pragma once
// A store as a traversal source (engine/traversal.h): values and records are looked up in the
// bricks that hold them, through a shared BrickCache, so extraction reads only the bricks its
// traversal reaches. A node's value is read from the coarsest band that holds it, and a
// diamond's record from its own band, so a coarse extraction never touches the finer bands.
#include <algorithm>
#include <array>
#include <cstdint>
#include <memory>

#include "engine/extract.h"
#include "engine/lattice.h"
#include "engine/record.h"
#include "engine/traversal.h"
#include "io/brick_cache.h"
#include "io/store_brick.h"

namespace isotope {

class PagedVolume {
 public:
  explicit PagedVolume(BrickCache& cache);

  const Lattice& lattice() const { return layout_.lattice(); }
  const std::array<int64_t, 3>& data_dims() const { return layout_.dims(); }
  const std::array<double, 3>& origin() const { return header_.origin; }
  const std::array<double, 3>& spacing() const { return header_.spacing; }
  double value_offset() const { return header_.value_offset; }
  double value_scale() const { return header_.value_scale; }

  class RecordView {
   public:
    explicit RecordView(const Record* r) : r_(r) {}
    const DiamondBounds& bounds() const { return r_->bounds; }
    const DiamondTopology& topology() const { return r_->topology; }

   private:
    const Record* r_;
  };

  // One per task. Keeps the last few bricks it used (direct-mapped by brick index), so most
  // lookups touch no shared state at all.
  class Reader {
   public:
    explicit Reader(const PagedVolume& volume) : volume_(&volume) {}
    // Band j's nodes beyond the data box hold the value of the nearest data node, like
    // MultiresVolume::value; a node beyond band j's grid is clamped and read where it lies.
    float value(const Coord& c, int j) {
      const StoreLayout& layout = volume_->layout_;
      const Band& band = layout.band(j);
      Coord q = c;
      if ((c[0] >> j) >= band.nodes[0] || (c[1] >> j) >= band.nodes[1] || (c[2] >> j) >= band.nodes[2]) {
        for (int a = 0; a < 3; ++a) q[a] = std::min(c[a], layout.dims()[a] - 1);
        j = scale_of(q, layout.lattice());
      }
      uint32_t m = 0;
      const DecodedBrick& b = brick(locate(j, q, &m));
      return b.values[m];
    }
    // The values of nodes lo .. lo + n (inclusive) into f (x fastest, rows `stride` apart) when
    // they lie in one band-0 brick and its halo; false, touching nothing, when they do not.
    bool block_values(const Coord& lo, const std::array<int64_t, 3>& n, float* f, int64_t stride) {
      const StoreLayout& layout = volume_->layout_;
      const int bits = layout.brick_bits();
      const Coord b{lo[0] >> bits, lo[1] >> bits, lo[2] >> bits};
      for (int a = 0; a < 3; ++a)
        if (lo[a] + n[a] > ((b[a] + 1) << bits) + 1) return false;  // the halo reaches 2 beyond, the block 1
      const float* halo = halo_values(layout.brick_index(0, {b[0], b[1], b[2]}));
      const Coord origin{b[0] << bits, b[1] << bits, b[2] << bits};
      for (int64_t z = 0; z <= n[2]; ++z)
        for (int64_t y = 0; y <= n[1]; ++y) {
          const float* row = halo + halo_index(layout, origin, {lo[0], lo[1] + y, lo[2] + z});
          std::copy(row, row + n[0] + 1, f + (z * stride + y) * stride);
        }
      return true;
    }
    struct Handle {
      int64_t index = 0;
      uint32_t m = 0;
    };
    Handle locate(uint64_t packed) const {
      const Coord v = traversal::unpack(packed);
      const int j = scale_of(v, volume_->layout_.lattice());
      Handle h;
      h.index = locate(j, v, &h.m);
      return h;
    }
    DiamondBounds bounds(const Handle& h, const RecordFields&) { return brick(h.index).records[brick_record_index(h.m)].bounds; }
    DiamondTopology topology(const Handle& h, const RecordFields&) {
      return brick(h.index).records[brick_record_index(h.m)].topology;
    }
    void prefetch(const Handle&) {}

   private:
    int64_t locate(int j, const Coord& c, uint32_t* morton) const {
      const int bits = volume_->layout_.brick_bits();
      const int64_t mask = volume_->layout_.brick_width() - 1;
      const int64_t x = c[0] >> j, y = c[1] >> j, z = c[2] >> j;
      *morton = brick_morton(x & mask, y & mask, z & mask, bits);
      return volume_->layout_.brick_index(j, {x >> bits, y >> bits, z >> bits});
    }
    const DecodedBrick& brick(int64_t index) {
      Pinned& p = pinned_[static_cast<size_t>(index) % pinned_.size()];
      if (p.index != index) {
        p.brick = volume_->cache_.get(index);
        p.index = index;
      }
      return *p.brick;
    }
    const float* halo_values(int64_t index) {
      PinnedHalo& p = pinned_halos_[static_cast<size_t>(index) % pinned_halos_.size()];
      if (p.index != index) {
        p.halo = volume_->cache_.get_halo_values(index);
        p.index = index;
      }
      return p.halo->values;
    }
    struct Pinned {
      int64_t index = -1;
      std::shared_ptr<const DecodedBrick> brick;
    };
    struct PinnedHalo {
      int64_t index = -1;
      std::shared_ptr<const HaloValues> halo;
    };
    const PagedVolume* volume_;
    std::array<Pinned, 16> pinned_;
    std::array<PinnedHalo, 4> pinned_halos_;
  };
  Reader reader() const { return Reader(*this); }

 private:
  BrickCache& cache_;
  const StoreLayout& layout_;
  const StoreHeader& header_;
};

// extract() (engine/extract.h) over a store, paged through the volume's cache.
Mesh extract(const PagedVolume& volume, const ExtractOptions& options, ExtractStats* stats = nullptr);

}  // namespace isotope
