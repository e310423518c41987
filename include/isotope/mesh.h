#pragma once
// An indexed, welded triangle mesh in physical coordinates, and what can be measured of it.
#include <array>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include <isotope/detail/huge_page_allocator.h>

namespace isotope {

struct Mesh {
  // Meshes run to hundreds of megabytes: in large blocks, and resize() leaves the new elements
  // unwritten (detail::UninitializedHugePageAllocator), for the writer to fill. A caller takes them
  // as the views below (pointer and count, whatever the allocator), and copies them where a
  // std::vector of its own is wanted: std::vector<std::array<float, 3>> v(m.vertices().begin(),
  // m.vertices().end()).
  template <class T>
  using Array = std::vector<T, detail::UninitializedHugePageAllocator<T>>;
  Array<std::array<float, 3>> positions;
  Array<std::array<uint32_t, 3>> triangles;  // counter-clockwise seen from the outside (value <= iso)

  std::span<const std::array<float, 3>> vertices() const { return positions; }
  std::span<const std::array<uint32_t, 3>> faces() const { return triangles; }
};

// Combinatorial measures of a triangle mesh: what "same topology" is checked against.
struct MeshTopology {
  int64_t vertices = 0;  // vertices referenced by at least one triangle
  int64_t triangles = 0;
  int64_t edges = 0;                 // distinct undirected edges
  int64_t components = 0;            // connected through shared vertices
  int64_t euler_characteristic = 0;  // V - E + F
  int64_t boundary_edges = 0;        // edges with one incident triangle
  int64_t nonmanifold_edges = 0;     // edges with three or more
};

// On all threads.
MeshTopology measure_topology(const Mesh& mesh);

// Per-vertex unit normals, for shading: the sum of the normals of the triangles around a vertex,
// each weighted by its area, so that small slivers of an adaptive mesh do not tilt a vertex that
// large triangles surround. Outward, as the triangles are counter-clockwise seen from outside. A
// vertex of only degenerate triangles gets 0.
std::vector<std::array<float, 3>> vertex_normals(const Mesh& mesh);

// Binary little-endian PLY (float x, y, z per vertex; uchar-counted int indices per face), written
// to a temporary file beside PATH and renamed when complete (docs/RELIABILITY.md, "Outputs": a
// device, FIFO or directory is refused, a link followed). Throws IoError.
void write_ply(const Mesh& mesh, const std::string& path);

// The format PATH's extension names, written as write_ply writes PLY (atomically; throws IoError,
// also for an extension that names no format): .ply (as write_ply), .obj (Wavefront text, every
// float in its shortest exact form), .stl (binary, a unit normal per triangle), .glb (glTF 2.0
// binary: positions, unit vertex normals, uint32 indices) or .vtp (VTK XML PolyData with point
// normals, for ParaView). docs/MESH_FORMATS.md says what each holds and which tools open it.
void write_mesh(const Mesh& mesh, const std::string& path);

}  // namespace isotope
