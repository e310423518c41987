#pragma once
// Marching tetrahedra with vertices welded by grid edge, so the mesh comes out indexed.
// Every mesh vertex lies on a grid edge (p, q) of the hierarchy; p + q (in lattice
// coordinates) is unique to that edge, so it is the vertex's key (docs/METHOD.md, "Stopping rule and extraction").
#include <algorithm>
#include <array>
#include <cstdint>
#include <utility>
#include <vector>

#include "engine/core/huge_blocks.h"
#include "engine/hierarchy/lattice.h"
#include "engine/mesh/edge_vertex_map.h"
#include "isotope/mesh.h"

namespace isotope {

// p + q of the edge whose vertex has this key (MeshBuilder, for a grid of `side` nodes per axis).
Coord edge_key_sum(uint64_t key, int64_t side);

// What marching tetrahedra makes of one tetrahedron, before any vertex is welded: the cut edges
// (pairs of corner indices) and the triangles over them, in the order and winding MeshBuilder emits
// them. Shared by MeshBuilder and by what counts the triangles a mesh will have after clipping to
// the data box (clipped_triangles), which must see the same triangles.
class TetCutter {
 public:
  // side: nodes per axis of the grid whose coordinates are passed in.
  TetCutter(float iso, int64_t side, const std::array<double, 3>& origin, const std::array<double, 3>& spacing);

  struct Cut {
    int points = 0;                                // cut edges: 0, 3 or 4
    std::array<std::array<int, 2>, 4> edges{};     // each a pair of corner indices
    int triangles = 0;                             // 0, 1 or 2
    std::array<std::array<int, 3>, 2> triangle{};  // indices into edges
  };
  Cut cut(const std::array<Coord, 4>& corners, const std::array<float, 4>& values, bool positive) const;
  // The welding key of grid edge (p, q) and the position of its vertex (physical coordinates).
  uint64_t edge_key(const Coord& p, const Coord& q) const {
    return edge_key_of_sum(p[0] + q[0], p[1] + q[1], p[2] + q[2]);
  }
  // The same key from p + q: p + q in brick order (16^3 doubled coordinates, i.e. the 8^3 node
  // bricks), so that edges met close together in the traversal get close keys, and the welding
  // table keeps them close in memory.
  uint64_t edge_key_of_sum(int64_t x, int64_t y, int64_t z) const {
    const int64_t brick = ((z >> 4) * key_bricks_ + (y >> 4)) * key_bricks_ + (x >> 4);
    return static_cast<uint64_t>(brick << 12 | (z & 15) << 8 | (y & 15) << 4 | (x & 15));
  }
  // Interpolated from the edge's first node in grid order (z, then y, then x), so every
  // tetrahedron sharing the edge computes the same bits. Inline: the finest march makes most of
  // its vertices here.
  std::array<float, 3> point(const Coord& p0, float f0, const Coord& q0, float f1) const {
    const bool swap = p0[2] != q0[2] ? q0[2] < p0[2] : p0[1] != q0[1] ? q0[1] < p0[1] : q0[0] < p0[0];
    const Coord& p = swap ? q0 : p0;
    const Coord& q = swap ? p0 : q0;
    const double fp = swap ? f1 : f0, fq = swap ? f0 : f1;
    const double t = (static_cast<double>(iso_) - fp) / (fq - fp);
    std::array<float, 3> pos;
    for (size_t a = 0; a < 3; ++a)
      pos[a] = static_cast<float>(origin_[a] +
                                  spacing_[a] * (static_cast<double>(p[a]) + t * static_cast<double>(q[a] - p[a])));
    return pos;
  }

 private:
  float iso_;
  int64_t key_bricks_;  // bricks per axis of the doubled lattice
  std::array<double, 3> origin_, spacing_;
};

class MeshBuilder {
 public:
  // side: nodes per axis of the grid whose coordinates are passed in. welds: a welding table lent
  // for this builder's life (emptied here), or null for one of its own.
  MeshBuilder(float iso, int64_t side, const std::array<double, 3>& origin, const std::array<double, 3>& spacing,
              EdgeVertexMap* welds = nullptr);
  MeshBuilder(const MeshBuilder&) = delete;  // a copy would weld into the original's table
  MeshBuilder& operator=(const MeshBuilder&) = delete;

  // Emits the 0, 1 or 2 triangles of one tetrahedron. `positive`: det(c1-c0, c2-c0, c3-c0) > 0.
  // Triangles are wound counter-clockwise seen from the outside (value <= iso); a quadrilateral
  // is split along the diagonal at its smallest edge key, so the triangle set does not depend on
  // the order of the corners.
  void add_tet(const std::array<Coord, 4>& corners, const std::array<float, 4>& values, bool positive);

  // The pieces of add_tet, for a kernel that cuts its tetrahedra itself and remembers the vertices
  // it made, welding them itself (march_block): a new vertex on edge (p, q), whose key is kept if
  // it lies on one of the builder's two planes, without the welding table; and a triangle.
  uint32_t unwelded_vertex(const Coord& p, float fp, const Coord& q, float fq) { return new_vertex(0, p, fp, q, fq); }
  void add_triangle(uint32_t a, uint32_t b, uint32_t c) {
    detail::grow_prefaulted(mesh_.triangles);
    mesh_.triangles.push_back({a, b, c});
  }

  // The triangles add_tet emits, unwelded (what a count of the mesh's triangles after clipping
  // builds again: clipped_triangles).
  const TetCutter& cutter() const { return cutter_; }

  Mesh take() { return std::move(mesh_); }
  // The edge key of every vertex, in vertex order (kept only when asked for, by keep_keys()):
  // what welds the meshes of separately built parts into one (weld).
  void keep_keys() { keep_keys_ = true; }
  std::vector<uint64_t> take_keys() { return std::move(keys_); }
  // A vertex on a plane z = const, with its edge key.
  struct PlaneVertex {
    uint32_t local;  // its index in this builder's mesh
    uint64_t key;
  };
  // Only the keys of the vertices whose edge (p, q) has p_z + q_z = BOTTOM or = TOP (-1: neither),
  // each list in vertex order: what a slab shares with the slabs below and above it
  // (march_in_slabs), without a key for every vertex.
  void keep_plane_keys(int64_t bottom, int64_t top) { plane_z2_ = {bottom, top}; }
  std::vector<PlaneVertex> take_bottom_keys() { return std::move(plane_keys_[0]); }
  std::vector<PlaneVertex> take_top_keys() { return std::move(plane_keys_[1]); }
  // Room for a mesh of about this size, in memory not touched until written: a builder that serves
  // one slab after another sizes the next mesh by the last, instead of growing it by doubling into
  // fresh pages each time.
  void reserve(size_t vertices, size_t triangles) {
    mesh_.positions.reserve(vertices);
    mesh_.triangles.reserve(triangles);
  }
  // The next mesh is built in STORAGE's arrays, emptied, their room kept: a builder that serves one
  // slab after another reuses the memory of a slab already joined instead of fresh pages.
  void build_in(Mesh storage) {
    storage.positions.clear();
    storage.triangles.clear();
    mesh_ = std::move(storage);
  }
  // Ready for another mesh on another grid or at another isovalue (as the constructor's), the
  // memory of its welding table and of its key lists kept, the table spanning what the last mesh
  // needed: a builder kept from one extraction for the next.
  void retarget(float iso, int64_t side, const std::array<double, 3>& origin, const std::array<double, 3>& spacing) {
    reset();
    cutter_ = TetCutter(iso, side, origin, spacing);
  }
  // The memory the builder holds: its mesh's arrays, its key lists and its welding table.
  size_t bytes() const {
    size_t b = mesh_.positions.capacity() * sizeof(mesh_.positions[0]) +
               mesh_.triangles.capacity() * sizeof(mesh_.triangles[0]) + keys_.capacity() * sizeof(uint64_t) +
               own_map_.bytes();
    for (const auto& k : plane_keys_) b += k.capacity() * sizeof(PlaneVertex);
    return b;
  }
  // Ready for another mesh with the same isovalue and grid, its welding table kept, spanning what
  // the last mesh needed (EdgeVertexMap::clear_at_size).
  void reset() {
    mesh_ = Mesh{};
    keys_.clear();
    plane_z2_ = {-1, -1};
    for (auto& k : plane_keys_) k.clear();
    map_->clear_at_size();
  }

 private:
  uint32_t vertex(uint64_t key, const Coord& p, float fp, const Coord& q, float fq) {
    const uint32_t found = map_->find_or_insert(key, static_cast<uint32_t>(mesh_.positions.size()));
    return found != EdgeVertexMap::kAbsent ? found : new_vertex(key, p, fp, q, fq);
  }
  // A new vertex on edge (p, q); KEY its edge key, or 0 when not computed yet (no edge has key 0:
  // its p + q would be the origin).
  uint32_t new_vertex(uint64_t key, const Coord& p, float fp, const Coord& q, float fq) {
    const auto fresh = static_cast<uint32_t>(mesh_.positions.size());
    detail::grow_prefaulted(mesh_.positions);
    mesh_.positions.push_back(cutter_.point(p, fp, q, fq));
    const int64_t z2 = p[2] + q[2];
    if (keep_keys_ || z2 == plane_z2_[0] || z2 == plane_z2_[1]) keep_key(fresh, key, p, q);
    return fresh;
  }
  // The key of new vertex FRESH kept, in the list of all keys or of its plane's.
  void keep_key(uint32_t fresh, uint64_t key, const Coord& p, const Coord& q);

  TetCutter cutter_;
  // Small at first: a builder of its own serves one mesh.
  EdgeVertexMap own_map_{64};
  EdgeVertexMap* map_ = &own_map_;
  Mesh mesh_;
  bool keep_keys_ = false;
  std::vector<uint64_t> keys_;
  std::array<int64_t, 2> plane_z2_{-1, -1};             // the bottom and top planes' p_z + q_z
  std::array<std::vector<PlaneVertex>, 2> plane_keys_;  // their vertices: bottom, top
};

}  // namespace isotope
