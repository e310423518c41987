#pragma once
// Marching tetrahedra over a box of finest cells whose node values sit in a small local array:
// the kernel of the finest-level extraction (engine/extract/finest_extract.h), where a box is a block of
// cells that range culling kept.
#include <array>
#include <cstdint>

#include "engine/hierarchy/lattice.h"
#include "engine/mesh/marching_tetrahedra.h"

namespace isotope {

// The box's cells have their lowest corner at base + (x, y, z), 0 <= x < cells[0] and so on;
// node (x, y, z) of the box (0 <= x <= cells[0]) has value f[(z * stride + y) * stride + x].
// Cells are walked z slowest, then y, then x; each cell's six Kuhn tetrahedra
// (engine/hierarchy/kuhn.h, cell_tetrahedra) in their order. The memo must hold a box of stride - 1 cells.
void march_block(const float* f, int64_t stride, const Coord& base, const std::array<int64_t, 3>& cells, float iso,
                 EdgeMemo& memo, MeshBuilder& builder);

}  // namespace isotope
