#pragma once
// Marching tetrahedra over a box of finest cells whose node values sit in a small local array:
// the kernel of the finest-level extraction (extract_finest), where a box is a block of
// cells that range culling kept.
#include <algorithm>
#include <array>
#include <cstdint>
#include <vector>

#include "engine/hierarchy/lattice.h"
#include "engine/mesh/marching_tetrahedra.h"

namespace isotope {

// A thread's scratch for marching boxes of cells: the vertices already made for the cut edges of
// one box, in an array slot per edge (by p + q in doubled coordinates from the box's lowest
// corner), in front of the welding table while a box is marched, since most cut edges are shared
// by several tetrahedra of a box and a slot is cheaper than a hash probe; and the sign of each
// node of the box, a row of nodes to a word. Forgets the vertices at the next start(), in O(1).
class EdgeMemo {
 public:
  // A box of at most `cells` cells per axis, fewer than 32.
  explicit EdgeMemo(int64_t cells)
      : width_(2 * cells + 1),
        slots_(static_cast<size_t>(width_ * width_ * width_), 0),
        rows_(static_cast<size_t>((cells + 1) * (cells + 1))) {}
  // A new box.
  void start() {
    if (++stamp_ == 0) {  // the stamps wrapped: no slot may look current
      std::fill(slots_.begin(), slots_.end(), 0);
      stamp_ = 1;
    }
  }
  // Slots per axis: the slot of p + q = (x, y, z) from the box's doubled lowest corner is
  // (z * width() + y) * width() + x.
  int64_t width() const { return width_; }
  // stamp() << 32 | vertex once filled in this box.
  uint64_t* slots() { return slots_.data(); }
  uint64_t stamp() const { return stamp_; }
  // A word per row of the box's nodes: bit x of row z * (cells + 1) + y is node (x, y, z)'s sign.
  uint32_t* rows() { return rows_.data(); }

 private:
  int64_t width_;
  uint64_t stamp_ = 0;
  std::vector<uint64_t> slots_;
  std::vector<uint32_t> rows_;
};

// The box's cells have their lowest corner at base + (x, y, z), 0 <= x < cells[0] and so on;
// node (x, y, z) of the box (0 <= x <= cells[0]) has value f[(z * stride + y) * stride + x].
// Cells are walked z slowest, then y, then x; each cell's six Kuhn tetrahedra
// (cell_tetrahedra) in their order, cut as MeshBuilder::add_tet cuts them,
// so the mesh is the one add_tet makes of them. The memo must hold a box of stride - 1 cells.
void march_block(const float* f, int64_t stride, const Coord& base, const std::array<int64_t, 3>& cells, float iso,
                 EdgeMemo& memo, MeshBuilder& builder);

}  // namespace isotope
