#pragma once
// The full-resolution baseline: marching tetrahedra over every finest Kuhn tetrahedron of the
// data's cells, no hierarchy. What the adaptive extraction must equal at eps = 0 (docs/DESIGN.md, invariant 2).
#include <array>
#include <cstdint>

#include "isotope/mesh.h"
#include "isotope/volume.h"

namespace isotope {

// Marching tetrahedra over every cell, on all threads (engine/core/parallel.h). The mesh is the same
// bit for bit whatever the number of threads: vertices numbered in order of first appearance in
// one walk over the cells, z slowest, then y, then x. Throws std::invalid_argument for a
// non-finite iso.
Mesh extract_full_resolution(const Volume& volume, float iso);

// Cell layers per slab, the unit of parallel work of extract_full_resolution(): slabs start at the
// multiples of it along z. A function of the dimensions only, so never of the thread count.
int64_t full_resolution_slab_layers(const std::array<int64_t, 3>& dims);

}  // namespace isotope
