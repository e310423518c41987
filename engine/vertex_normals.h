#pragma once
// Per-vertex unit normals of a mesh, for shading: the sum of the normals of the triangles around a
// vertex, each weighted by its area (the cross product's length does that for free), so that small
// slivers of an adaptive mesh do not tilt a vertex that large triangles surround. Outward, as the
// triangles are counter-clockwise seen from outside. A vertex of only degenerate triangles gets 0.
#include <array>
#include <vector>

#include "engine/mesh.h"

namespace isotope {

std::vector<std::array<float, 3>> vertex_normals(const Mesh& mesh);

}  // namespace isotope
