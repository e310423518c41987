#pragma once
// Adaptive isosurface extraction over the bisection hierarchy (paper Sec. 3.2 with the stopping
// rule of design.md) and the full-resolution baseline it must equal at eps = 0.
#include <cstdint>

#include "engine/mesh.h"
#include "engine/multires_volume.h"
#include "engine/options.h"
#include "engine/volume.h"

namespace isotope {

struct ExtractStats {
  int64_t tets_visited = 0;
  int64_t tets_emitted = 0;  // stopping tetrahedra that were handed to marching tetrahedra
  double seconds = 0;
};

// Throws std::invalid_argument for a non-finite iso, eps < 0 or delta < 0.
Mesh extract(const MultiresVolume& mv, const ExtractOptions& options, ExtractStats* stats = nullptr);

// Marching tetrahedra over every finest Kuhn tetrahedron of the data's cells, no hierarchy.
Mesh extract_full_resolution(const Volume& volume, float iso);

}  // namespace isotope
