#pragma once
// One tile of one band of the banded build (StoreLayout): the records of the scale-j
// nodes of a box of G_j, computed from the values of that box plus a halo of two nodes and, for
// j > 0, the records of the scale j-1 cube centres (one per G_j cell), which band j-1 produced.
// Nothing else is needed: a cube centre's record depends on nodes at most two G_j steps away
// (its face-centre children one step along one axis, their edge-midpoint children one step in
// the face, whose polyhedra reach one step further), so bands are built one after the other,
// tile by tile, in memory bounded by the tile. The records are bit for bit those of
// MultiresVolume::build: both run RecordBuilder on the same inputs.
#include <array>
#include <cstdint>
#include <utility>
#include <vector>

#include "engine/core/huge_blocks.h"
#include "engine/hierarchy/diamond.h"
#include "engine/hierarchy/record.h"
#include "engine/hierarchy/record_builder.h"
#include "engine/hierarchy/store_layout.h"

namespace isotope {

class BandTile {
 public:
  // The tile's arrays, handed from one tile to the next so that their pages are touched once,
  // not faulted in again for every tile.
  template <class T>
  using Array = std::vector<T, detail::HugePageAllocator<T>>;  // a large tile's hundreds of MB, in few page faults
  struct Buffers {
    Array<float> values;
    Array<Record> records, children;
  };

  // Band j, core = G_j nodes [core_lo, core_hi) per axis.
  BandTile(const StoreLayout& layout, int band, const Box3& core_lo, const Box3& core_hi, Buffers buffers = {});
  Buffers release() { return {std::move(values_), std::move(records_), std::move(children_)}; }

  // The window of a core: the nodes its records read, one or two more below it and two above,
  // within the lattice (G_j units, inclusive).
  static std::pair<Box3, Box3> window_of(const StoreLayout& layout, int band, const Box3& core_lo, const Box3& core_hi);
  // What band j+1 needs of a core (next_lo, next_hi below).
  static std::pair<Box3, Box3> next_of(const StoreLayout& layout, int band, const Box3& core_lo, const Box3& core_hi);
  // This tile's window.
  const Box3& window_lo() const { return lo_; }
  const Box3& window_hi() const { return hi_; }
  Box3 window_size() const { return {hi_[0] - lo_[0] + 1, hi_[1] - lo_[1] + 1, hi_[2] - lo_[2] + 1}; }
  const Box3& core_lo() const { return core_lo_; }
  const Box3& core_hi() const { return core_hi_; }

  // Inputs, x fastest, filled before build(). Values of every window node; beyond the band's
  // grid, that of the nearest grid node. For j > 0, the record of the scale j-1 cube centre of
  // each window cell (cell i spans nodes i and i+1), window_size - 1 per axis; entries whose
  // centre lies beyond record_extent are never read.
  Array<float>& values() { return values_; }
  Array<Record>& children() { return children_; }

  // Computes the records of the core's scale-j nodes (and of the halo nodes they depend on).
  // Without `topology`, their range and errors only (critical intervals empty, weights 0, no
  // critical point counted): what an extraction in mode none reads, for a fraction of the work.
  // Without `weights`, no simplification weights (0): what every mode but simplify reads.
  // The critical points counted are those of the core, or of the part of it set by count_only
  // (a core widened to hand a fused band its halo, whose nodes other tiles count).
  void build(CriticalCounts& counts, bool topology = true, bool weights = true);
  void count_only(const Box3& lo, const Box3& hi) { count_lo_ = lo, count_hi_ = hi; }
  const Box3& count_lo() const { return count_lo_; }
  const Box3& count_hi() const { return count_hi_; }

  // G_j coordinates: node_value() anywhere in the window, node_record() of computed scale-j nodes.
  const float& node_value(const Box3& g) const { return values_[static_cast<size_t>(index(g, size_))]; }
  const Record& node_record(const Box3& g) const { return records_[static_cast<size_t>(index(g, size_))]; }
  const Record& child_record(const Box3& cell) const { return children_[static_cast<size_t>(index(cell, cells_))]; }
  // What band j+1 needs from this tile, for its nodes g in [next_lo, next_hi) (G_{j+1} units):
  // the value at 2g and the record of the cube centre 2g + 1, its cell g's child. The last tile
  // along an axis also covers band j+1's nodes one step beyond band j's grid.
  const Box3& next_lo() const { return next_lo_; }
  const Box3& next_hi() const { return next_hi_; }
  float next_value(const Box3& g) const { return node_value({2 * g[0], 2 * g[1], 2 * g[2]}); }
  Record next_child(const Box3& g) const;
  // Nodes x0 .. x1 - 1 of row (y, z) of band j+1's grid: next_value of each, and next_child of
  // each (or of the first child_count).
  void next_row(int64_t x0, int64_t x1, int64_t y, int64_t z, float* values, Record* children,
                int64_t child_count = -1) const;

  const StoreLayout& layout() const { return layout_; }
  int band() const { return j_; }

  // RecordBuilder's grid (lattice coordinates).
  const Lattice& lattice() const { return layout_.lattice(); }
  const std::array<int64_t, 3>& data_dims() const { return layout_.dims(); }
  float value(const Coord& c) const;
  bool child(const Coord& u, Record& r) const;
  void store(const Coord& v, const Record& r);

 private:
  int64_t index(const Box3& g, const Box3& size) const {
    return ((g[2] - lo_[2]) * size[1] + (g[1] - lo_[1])) * size[0] + (g[0] - lo_[0]);
  }
  bool computable(const Box3& g, int odd) const;

  // A diamond's polyhedron and children as offsets in the window's arrays. The geometry of a
  // scale-j vertex depends only on its G_j coordinates mod 4 (diamond_of), so one
  // template per class serves every vertex whose diamond lies inside the data box: no
  // coordinates, no mirroring, no existence checks. The offsets depend on the window's size
  // alone, so the tiles of a band, most of one size, share their templates (per thread). The
  // shape and its gradients (1.5 KB a class, most of a template) depend on neither the
  // window nor the thread: made once a process (geometry_of), each template points to them.
  struct DiamondGeometry {
    DiamondShape shape;
    ShapeGradients gradients;
  };
  static const DiamondGeometry& geometry_of(const Lattice& l, int j, int parity, const Diamond& d);
  struct DiamondTemplate {
    bool ready = false;
    PolyhedronType type = PolyhedronType::cube;
    const DiamondGeometry* geometry = nullptr;
    int ring_count = 0, same_count = 0, cube_count = 0;
    int64_t a = 0, b = 0, ring[8] = {};  // into values_
    int64_t same[8] = {};                // into records_: children of scale j
    int64_t cube[8] = {};                // into children_: scale j-1 cube centres
  };
  // A thread's eight sets of 64 (shared_templates) in about 4 pages each, not 28.
  static_assert(sizeof(DiamondTemplate) <= 256, "a template holds offsets; its geometry is shared");
  const DiamondTemplate& template_for(const Box3& g);
  bool inside_data_box(const Box3& g) const;
  // The record of the node at `base` in the window's arrays (index()), `cell` its cell's index.
  void build_fast(int64_t base, int64_t cell, const DiamondTemplate& t, CriticalCounts& counts, bool topology);
  // This thread's templates for windows of this tile's band and size, made as first asked for.
  static DiamondTemplate* shared_templates(int k, int j, const Box3& size, const Box3& cells);
  bool weights_ = true;  // this build's (build())
  DiamondTemplate* templates_ = nullptr;
  // Band 0: per 4^3 block of the window, whether every value within 4 nodes of it is one and the
  // same (most of a CT scan's background). Such a block's records are known without computing.
  void find_constant_blocks();
  std::vector<uint8_t> constant_;  // per block: 1 when constant around it
  bool signed_zero_ = false;       // some value of the window is -0
  Box3 blocks_{};

  const StoreLayout& layout_;
  int j_;
  Box3 core_lo_, core_hi_, count_lo_, count_hi_, lo_{}, hi_{}, size_{}, cells_{}, next_lo_{}, next_hi_{};
  int64_t top_ = 0;  // n >> j: the lattice's far face in G_j units
  Array<float> values_;
  Array<Record> records_;
  Array<Record> children_;
};

}  // namespace isotope
