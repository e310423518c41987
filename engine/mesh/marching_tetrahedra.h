#pragma once
// Marching tetrahedra with vertices welded by grid edge, so the mesh comes out indexed.
// Every mesh vertex lies on a grid edge (p, q) of the hierarchy; p + q (in lattice
// coordinates) is unique to that edge, so it is the vertex's key (docs/METHOD.md, "Stopping rule and extraction").
#include <algorithm>
#include <array>
#include <cstdint>
#include <vector>

#include "engine/hierarchy/lattice.h"
#include "engine/mesh/edge_vertex_map.h"
#include "isotope/mesh.h"

namespace isotope {

// p + q of the edge whose vertex has this key (MeshBuilder, for a grid of `side` nodes per axis).
Coord edge_key_sum(uint64_t key, int64_t side);

// The vertices already made for the cut edges of one box of cells, in an array slot per edge (by
// its p + q): in front of the welding table while a box is marched (engine/extract/block_march.cpp),
// since most cut edges are shared by several tetrahedra of a box and a slot is cheaper than a
// hash probe. Forgets everything at the next start(), in O(1).
class EdgeMemo {
 public:
  // A box of at most `cells` cells per axis.
  explicit EdgeMemo(int64_t cells) : width_(2 * cells + 1), slots_(static_cast<size_t>(width_ * width_ * width_), 0) {}
  // A new box: CELLS per axis from BASE.
  void start(const Coord& base, const std::array<int64_t, 3>& cells) {
    base2_ = {2 * base[0], 2 * base[1], 2 * base[2]};
    end2_ = {2 * cells[0], 2 * cells[1], 2 * cells[2]};
    if (++stamp_ == 0) {  // the stamps wrapped: no slot may look current
      std::fill(slots_.begin(), slots_.end(), 0);
      stamp_ = 1;
    }
  }
  // The slot of edge (p, q), both in the box: stamp << 32 | vertex once filled in this box.
  uint64_t& slot(const Coord& p, const Coord& q) {
    const int64_t x = p[0] + q[0] - base2_[0], y = p[1] + q[1] - base2_[1], z = p[2] + q[2] - base2_[2];
    return slots_[static_cast<size_t>((z * width_ + y) * width_ + x)];
  }
  uint64_t stamp() const { return stamp_; }
  // Edge (p, q) lies inside the box, on none of its faces: only the box's own cells have it, so no
  // other box will ask for its vertex.
  bool interior(const Coord& p, const Coord& q) const {
    const int64_t x = p[0] + q[0] - base2_[0], y = p[1] + q[1] - base2_[1], z = p[2] + q[2] - base2_[2];
    return x > 0 && x < end2_[0] && y > 0 && y < end2_[1] && z > 0 && z < end2_[2];
  }

 private:
  int64_t width_;
  Coord base2_{}, end2_{};
  uint64_t stamp_ = 0;
  std::vector<uint64_t> slots_;
};

// What marching tetrahedra makes of one tetrahedron, before any vertex is welded: the cut edges
// (pairs of corner indices) and the triangles over them, in the order and winding MeshBuilder emits
// them. Shared by MeshBuilder and by what counts the triangles a mesh will have after clipping to
// the data box (engine/mesh/box_clip.h), which must see the same triangles.
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
  uint64_t edge_key(const Coord& p, const Coord& q) const;
  std::array<float, 3> point(const Coord& p, float fp, const Coord& q, float fq) const;

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
  // With a memo, the corners must lie in its current box.
  void add_tet(const std::array<Coord, 4>& corners, const std::array<float, 4>& values, bool positive,
               EdgeMemo* memo = nullptr);

  // The triangles add_tet emits, unwelded (what a count of the mesh's triangles after clipping
  // builds again: engine/mesh/box_clip.h).
  const TetCutter& cutter() const { return cutter_; }

  Mesh take() { return std::move(mesh_); }
  // The edge key of every vertex, in vertex order (kept only when asked for, by keep_keys()):
  // what welds the meshes of separately built parts into one (engine/mesh/piece_weld.cpp,
  // engine/extract/full_resolution.cpp).
  void keep_keys() { keep_keys_ = true; }
  std::vector<uint64_t> take_keys() { return std::move(keys_); }
  // A vertex on a plane z = const, with its edge key.
  struct PlaneVertex {
    uint32_t local;  // its index in this builder's mesh
    uint64_t key;
  };
  // Only the keys of the vertices whose edge (p, q) has p_z + q_z = BOTTOM or = TOP (-1: neither),
  // each list in vertex order: what a slab shares with the slabs below and above it
  // (engine/extract/slab_march.cpp), without a key for every vertex.
  void keep_plane_keys(int64_t bottom, int64_t top) { plane_z2_ = {bottom, top}; }
  std::vector<PlaneVertex> take_plane_keys(int plane) { return std::move(plane_keys_[static_cast<size_t>(plane)]); }
  // Ready for another mesh with the same isovalue and grid, its welding table kept at its size.
  void reset() {
    mesh_ = Mesh{};
    keys_.clear();
    for (auto& k : plane_keys_) k.clear();
    map_->clear();
  }

 private:
  uint32_t vertex(uint64_t key, const Coord& p, float fp, const Coord& q, float fq);
  // A new vertex on edge (p, q); KEY its edge key, or 0 when not computed yet (no edge has key 0:
  // its p + q would be the origin).
  uint32_t new_vertex(uint64_t key, const Coord& p, float fp, const Coord& q, float fq);

  TetCutter cutter_;
  // Small at first: a builder of its own serves one mesh.
  EdgeVertexMap own_map_{64};
  EdgeVertexMap* map_ = &own_map_;
  Mesh mesh_;
  bool keep_keys_ = false;
  std::vector<uint64_t> keys_;
  std::array<int64_t, 2> plane_z2_{-1, -1};
  std::array<std::vector<PlaneVertex>, 2> plane_keys_;
};

}  // namespace isotope
