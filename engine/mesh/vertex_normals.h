#pragma once
// Vertex normals into an array the caller provides (isotope::vertex_normals is this into a
// zero-filled vector): every element written, so the array need not be zero-filled first.
#include <array>
#include <span>

#include "isotope/mesh.h"

namespace isotope {

// OUT (one element per vertex, else std::invalid_argument) gets each vertex's unit normal, or NONE
// for a vertex of only degenerate triangles (or of none): every element written, on all threads, so
// an array not filled before is first touched by the thread that writes each part of it.
void vertex_normals_into(const Mesh& mesh, std::span<std::array<float, 3>> out, const std::array<float, 3>& none);

}  // namespace isotope
