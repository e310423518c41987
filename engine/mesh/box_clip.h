#pragma once
// Clipping a mesh to the data box (docs/METHOD.md, "Volumes that are not (2^k+1)^3"). Where the
// data box is smaller than the lattice, a coarse tetrahedron may reach past a far face of the box;
// its triangles are cut at that face, which is where the data ends.
//
// Each triangle is clipped against the far faces in axis order, and each piece left is split as a
// fan from its first corner, so what a triangle becomes depends on its three corners alone. A new
// vertex lies where an edge from a corner inside to one outside meets the face; it is computed
// from the inside corner, so both triangles along that edge compute the same bits, and in a mesh
// it is welded by that edge: the clipped mesh is as crack-free as the mesh was.
#include <array>
#include <cstddef>
#include <cstdint>

#include "engine/hierarchy/lattice.h"
#include "engine/mesh/marching_tetrahedra.h"
#include "isotope/mesh.h"

namespace isotope {

struct BoxClip {
  using Point = std::array<float, 3>;  // physical coordinates, as a mesh holds them
  std::array<float, 3> face{};         // the far face along each axis, in physical coordinates
  std::array<bool, 3> active{};        // whether that face lies inside the lattice (else nothing is past it)
  bool any() const { return active[0] || active[1] || active[2]; }

  // The box of `dims` data nodes on a lattice of n + 1 nodes per axis, as a mesh built with this
  // origin and spacing places it.
  static BoxClip of(const std::array<int64_t, 3>& dims, int64_t n, const std::array<double, 3>& origin,
                    const std::array<double, 3>& spacing);
};

// How many triangles the triangle (a, b, c) becomes (0 to 8): what clip_to_box leaves of it.
int clipped_triangles(const BoxClip& box, const BoxClip::Point& a, const BoxClip::Point& b, const BoxClip::Point& c);

// How many triangles marching tetrahedra's of one tetrahedron (`cutter`, as MeshBuilder::add_tet
// emits them) become: what clip_to_box leaves of them in the welded mesh, since the vertices there
// have the same positions.
int clipped_triangles(const BoxClip& box, const TetCutter& cutter, const std::array<Coord, 4>& corners,
                      const std::array<float, 4>& values, bool positive);

// Clips every triangle of `mesh` to the box, in place: the triangles keep their order (each
// replaced by what is left of it), the vertices theirs, new ones follow, and vertices no triangle
// uses any more are dropped. Nothing changes where no triangle reaches past the box.
void clip_to_box(Mesh& mesh, const BoxClip& box);
// The same, its passes run in parallel over blocks of `block` triangles (and vertices): the mesh it
// leaves does not depend on the block size.
void clip_to_box(Mesh& mesh, const BoxClip& box, size_t block);

// The triangles `mesh` will have after clip_to_box, without clipping it.
int64_t clipped_triangles(const Mesh& mesh, const BoxClip& box);

}  // namespace isotope
