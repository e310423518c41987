#pragma once
// The full-resolution baseline: marching tetrahedra over every finest Kuhn tetrahedron of the
// data's cells, no hierarchy. What the adaptive extraction must equal at eps = 0 (docs/DESIGN.md, invariant 2).
#include <array>
#include <cstdint>

#include "isotope/mesh.h"
#include "isotope/volume.h"

namespace isotope {

// Marching tetrahedra over every cell, on all threads (parallel_for). The mesh is the same
// bit for bit whatever the number of threads: vertices numbered in order of first appearance in
// one walk over the cells, z slowest, then y, then x. Throws InvalidInput for a
// non-finite iso.
Mesh extract_full_resolution(const Volume& volume, float iso);

// The triangles extract_full_resolution() makes of the volume at iso, counted without making a
// mesh: per cell, from the signs of its eight nodes, through a table of what its six Kuhn
// tetrahedra make of each sign case (one for each parity of the cell, whose diagonal the
// tetrahedra share runs from its all-even corner). A compare and a lookup per cell, where the march
// builds and welds vertices: what a triangle budget asks first, whether the full-resolution mesh
// fits it. Throws InvalidInput for a non-finite iso.
int64_t count_full_resolution_triangles(const Volume& volume, float iso);

// Cell layers per slab, the unit of parallel work of extract_full_resolution(): slabs start at the
// multiples of it along z. A function of the dimensions only, so never of the thread count.
int64_t full_resolution_slab_layers(const std::array<int64_t, 3>& dims);

}  // namespace isotope
