#pragma once
// Vertex normals into an array the caller provides (isotope::vertex_normals is this into a
// zero-filled vector): every element written, so the array need not be zero-filled first; or
// handed to the caller run by run, into no array at all.
#include <array>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <span>

#include "isotope/mesh.h"

namespace isotope {

// OUT (one element per vertex, else InvalidInput) gets each vertex's unit normal, or NONE
// for a vertex of only degenerate triangles (or of none): every element written, on all threads, so
// an array not filled before is first touched by the thread that writes each part of it.
void vertex_normals_into(const Mesh& mesh, std::span<std::array<float, 3>> out, const std::array<float, 3>& none);

// The same normals handed out as they are finished, in runs of at most kNormalsPerRun consecutive
// vertices: DONE(first, normals) gets those of vertices [first, first + normals.size()), on any
// thread, each vertex in exactly one run, in a buffer lent to the next run once DONE returns. A
// writer so puts them in its file with no array of the mesh's size held between (fresh pages of
// that size cost more than the normals themselves on the reference machine).
inline constexpr size_t kNormalsPerRun = size_t{1} << 16;
using NormalsRun = std::function<void(uint32_t first, std::span<const std::array<float, 3>> normals)>;
void for_each_vertex_normals_run(const Mesh& mesh, const std::array<float, 3>& none, const NormalsRun& done);

}  // namespace isotope
