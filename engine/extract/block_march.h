#pragma once
// Marching tetrahedra over a box of finest cells whose node values sit in a small local array:
// the kernel of the finest-level extraction (extract_finest), where a box is a block of
// cells that range culling kept.
#include <algorithm>
#include <array>
#include <cstdint>
#include <memory>
#include <utility>
#include <vector>

#include "engine/core/huge_blocks.h"
#include "engine/hierarchy/lattice.h"
#include "engine/mesh/marching_tetrahedra.h"

namespace isotope {

// A thread's scratch for marching the boxes of one slab a row of boxes at a time: the vertex
// made for each cut edge of the current row of boxes, in an array slot per edge (by p + q in
// doubled coordinates: x across the whole slab, y from the row's lowest, z from the slab's lowest),
// and the sign of each node of the box being marched, a row of nodes to a word. An edge shared by
// two boxes of a row, or by a box and one of the row before (the row's lowest plane, carried over
// from the last row's highest), finds its vertex in its slot, so that no welding table is needed
// within a slab: a slab's boxes are marched by one builder alone, and the vertices of its lowest
// and highest planes are welded to the next slabs' by their kept keys (march_in_slabs). Flying
// Edges keeps its vertices in slots by row in the same way; a hash probe per edge on a box's faces
// cost 15-20% of the march, more on two threads sharing a cache. Forgets the vertices at the next
// start_slab(), in O(1).
class EdgeMemo {
 public:
  EdgeMemo() = default;
  // Boxes of at most `cells` cells per axis, fewer than 32, in a slab of `nodes_x` nodes along x.
  void reshape(int64_t cells, int64_t nodes_x) {
    const int64_t wx = 2 * std::max<int64_t>(1, nodes_x - 1) + 1;
    wyz_ = 2 * cells + 1;
    const auto slots = static_cast<size_t>(wx * wyz_ * wyz_);
    if (slot_count_ < slots) {
      // On huge pages: up to megabytes a thread, whose 4 KB pages faulted one by one cost a
      // one-shot 257^3 extraction 5% (docs/METHOD.md, "Fresh memory").
      slots_ = detail::make_huge_array<uint64_t>(slots);
      std::fill(slots_.get(), slots_.get() + slots, uint64_t{0});
      slot_count_ = slots;
      stamp_ = 0;
    }
    rows_.resize(static_cast<size_t>((cells + 1) * (cells + 1)));
  }
  // A new slab: no vertex known. A slot keeps the low 32 bits of its stamp: the stamps start over
  // (the slots zeroed) at a slab's start once they pass kStampLimit, which leaves a slab's rows
  // (a stamp each) room below 2^32.
  void start_slab() {
    if (stamp_ >= kStampLimit) {
      std::fill(slots_.get(), slots_.get() + slot_count_, uint64_t{0});
      stamp_ = 0;
    }
    ++stamp_;
    boxes_.clear();
  }
  static constexpr uint64_t kStampLimit = uint64_t{1} << 31;
  // Tests: the stamps as if `to` had been reached, to run the start over.
  void advance_stamp_to(uint64_t to) { stamp_ = std::max(stamp_, to); }
  // The next row of boxes of the slab: the vertices of the last row's highest plane (p_y + q_y =
  // 2 * cells from its lowest) become this row's lowest (0), the rest are forgotten. Only the
  // boxes marched in the last row have vertices there: a smooth surface culls most boxes, and
  // copying whole planes cost a 257^3 extraction 10%.
  void start_row() {
    const uint64_t last = stamp_++;
    const int64_t top = wyz_ - 1;
    for (const auto& [x0, x1] : boxes_)
      for (int64_t x = x0; x <= x1; ++x)
        for (int64_t z = 0; z < wyz_; ++z) {
          uint64_t* line = slots_.get() + (x * wyz_ + z) * wyz_;
          line[0] = line[top] >> 32 == last ? stamp_ << 32 | (line[top] & 0xffffffffu) : 0;
        }
    boxes_.clear();
  }
  // A box marched in this row, its doubled x from x0 to x1 (march_block).
  void marched(int64_t x0, int64_t x1) { boxes_.emplace_back(x0, x1); }
  // Slots per axis: the slot of p + q = (x, y, z) (x from the slab's doubled lowest corner, y
  // from the row's, z from the slab's) is (x * width_yz() + z) * width_yz() + y: x slowest, so
  // that a box's slots are one run of memory (a box's 17^3 slots spread over 289 pages, with x
  // fastest across a 2049-node slab, missed the TLB on most lines).
  int64_t width_yz() const { return wyz_; }
  // stamp() << 32 | vertex once filled in this row.
  uint64_t* slots() { return slots_.get(); }
  uint64_t stamp() const { return stamp_; }
  // A word per row of the box's nodes: bit x of row z * (cells + 1) + y is node (x, y, z)'s sign.
  uint32_t* rows() { return rows_.data(); }

 private:
  int64_t wyz_ = 1;
  uint64_t stamp_ = 0;
  std::vector<std::pair<int64_t, int64_t>> boxes_;  // marched in this row: doubled x, first and last
  detail::HugeArray<uint64_t> slots_;
  size_t slot_count_ = 0;
  std::vector<uint32_t> rows_;
};

// A memo lent for the march of one slab and given back at the end of its scope, so that the next
// slab's march finds memory already touched (a slab of a 2049-node-wide volume takes 9 MB of
// slots); give_back_edge_memos() lets the memos given back go (a server gone idle).
class LentEdgeMemo {
 public:
  LentEdgeMemo();
  ~LentEdgeMemo();
  LentEdgeMemo(const LentEdgeMemo&) = delete;
  LentEdgeMemo& operator=(const LentEdgeMemo&) = delete;
  EdgeMemo& operator*() { return *memo_; }

 private:
  std::unique_ptr<EdgeMemo> memo_;
};
void give_back_edge_memos();

// The box's cells have their lowest corner at base + (x, y, z), 0 <= x < cells[0] and so on;
// node (x, y, z) of the box (0 <= x <= cells[0]) has value f[(z * stride + y) * stride + x].
// Cells are walked z slowest, then y, then x; each cell's six Kuhn tetrahedra
// (cell_tetrahedra) in their order, cut as MeshBuilder::add_tet cuts them,
// so the mesh is the one add_tet makes of them, welded as the builder's table would weld it,
// provided the builder marches one slab one box deep (cells[2] <= stride - 1 from slab_z) and
// keeps the keys of its two planes (march_in_slabs), and the memo was started for that slab and
// for each row of its boxes in turn (march_finest_layers). The memo must hold boxes of
// stride - 1 cells; base is the box's lowest corner, on the lowest plane of its row (y) and of its
// slab (z).
void march_block(const float* f, int64_t stride, const Coord& base, const std::array<int64_t, 3>& cells, float iso,
                 EdgeMemo& memo, MeshBuilder& builder);

}  // namespace isotope
