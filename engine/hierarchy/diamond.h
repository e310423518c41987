#pragma once
// The diamond of a refinement vertex, computed from its integer coordinates alone
// (docs/METHOD.md, "Hierarchy from coordinates"): its refinement edge (a, b), its level, and the ring of
// polyhedron vertices around the edge, so that the tetrahedra of the diamond are
// (a, b, ring[i], ring[i+1 mod r]) (paper Sec. 4.2, Figure 2).
#include <array>
#include <cstdint>

#include "engine/hierarchy/lattice.h"

namespace isotope {

enum class PolyhedronType : uint8_t { cube = 0, octahedron = 1, diamond = 2 };

constexpr int ring_size(PolyhedronType t) {
  return t == PolyhedronType::cube ? 6 : t == PolyhedronType::octahedron ? 4 : 8;
}

struct Diamond {
  Coord v{}, a{}, b{};  // refinement vertex and the endpoints of its refinement edge
  PolyhedronType type = PolyhedronType::cube;
  int level = 0;  // level of the tetrahedra bisected at v
  int ring_count = 0;
  std::array<Coord, 8> ring{};  // in cycle order; may lie outside the lattice (cut diamonds)
};

// v must be a lattice node other than the eight corners of the domain.
Diamond diamond_of(const Coord& v, const Lattice& lattice);

// Midpoint of the unique longest edge of a tetrahedron: its refinement vertex (paper Sec. 3.1).
// Only meaningful when that midpoint is a lattice node (the tetrahedron is not a leaf).
Coord longest_edge_midpoint(const std::array<Coord, 4>& tet);

// Reflection of a coordinate across the domain faces, for the missing vertices of cut
// diamonds (paper Sec. 4.3).
Coord mirror_into(const Coord& c, const Lattice& lattice);

}  // namespace isotope
