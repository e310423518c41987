#pragma once
// Adaptive isosurface extraction over the bisection hierarchy (paper Sec. 3.2 with the stopping
// rule of design.md), and the full-resolution baseline it must equal at eps = 0.
#include <cstdint>

#include "engine/full_resolution.h"  // the baseline, offered with the extraction it checks
#include "engine/mesh.h"
#include "engine/multires_volume.h"
#include "engine/options.h"
#include "engine/volume.h"

namespace isotope {

struct ExtractStats {
  int64_t tets_visited = 0;
  int64_t tets_emitted = 0;  // stopping tetrahedra that were handed to marching tetrahedra
  // Simplify mode: stopping tetrahedra that preserve would have refined (a critical point below
  // fires at the isovalue, but its weight is under delta). 0 means the mesh is preserve's.
  int64_t tets_simplified = 0;
  double seconds = 0;
  // With max_triangles: the eps chosen (in data units), and the next finer eps step and the
  // triangles it would give (next_triangles = 0 when the chosen mesh is already full resolution).
  double chosen_eps = 0;
  double next_eps = 0;
  int64_t next_triangles = 0;
  int64_t budget_steps = 0;  // distinct eps values the budget search went through
  // With auto_delta: the delta chosen (in data units; -1 when none was), and the triangles of its
  // coarsest mesh (eps = infinity).
  double chosen_delta = -1;
  int64_t delta_floor_triangles = 0;
};

// Throws std::invalid_argument for a non-finite iso, eps < 0, delta < 0, a focus radius <= 0,
// and std::runtime_error when max_triangles is below the coarsest mesh the topology mode allows.
Mesh extract(const MultiresVolume& mv, const ExtractOptions& options, ExtractStats* stats = nullptr);

// One shot from an array, with only the hierarchy the options need: at eps = 0 (no triangle
// budget) none at all, since the mesh is marching tetrahedra over every cut cell
// (engine/finest_extract.h); otherwise the compact hierarchy (engine/hierarchy.h) with the record
// fields the mode reads. The same mesh, byte for byte, as extract() of the volume's hierarchy, or
// of its store. Throws as extract() does, and std::invalid_argument for
// dimensions below 2 or non-finite values.
Mesh extract(const Volume& volume, const ExtractOptions& options, ExtractStats* stats = nullptr);

// Whether extract(volume, options) needs a hierarchy (eps > 0, or a triangle budget).
bool needs_hierarchy(const ExtractOptions& options);

}  // namespace isotope
