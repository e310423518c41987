#include "engine/mesh/piece_weld.h"

#include "engine/core/parallel.h"
#include "engine/mesh/edge_vertex_map.h"
#include "engine/mesh/marching_tetrahedra.h"

namespace isotope {
namespace {

// Whether the point s (doubled lattice coordinates, p + q of an edge inside the tetrahedron) lies
// on one of its faces. Exact in 64 bits for lattices up to 2^20 cells per axis.
bool on_boundary(const Tet& t, const Coord& s) {
  static constexpr int kFaces[4][3] = {{1, 2, 3}, {0, 2, 3}, {0, 1, 3}, {0, 1, 2}};
  for (const auto& f : kFaces) {
    const Coord& a = t[f[0]];
    Coord u, v, w;
    for (int i = 0; i < 3; ++i) {
      u[i] = 2 * (t[f[1]][i] - a[i]);
      v[i] = 2 * (t[f[2]][i] - a[i]);
      w[i] = s[i] - 2 * a[i];
    }
    const int64_t d =
        w[0] * (u[1] * v[2] - u[2] * v[1]) - w[1] * (u[0] * v[2] - u[2] * v[0]) + w[2] * (u[0] * v[1] - u[1] * v[0]);
    if (d == 0) return true;
  }
  return false;
}

}  // namespace

Mesh weld(std::vector<PartMesh>& parts, int64_t side, bool room_to_clip) {
  // Which vertices are shared candidates, per part, in parallel.
  std::vector<std::vector<bool>> shared(parts.size());
  parallel_for(int64_t{0}, static_cast<int64_t>(parts.size()), [&](int64_t i) {
    const PartMesh& p = parts[static_cast<size_t>(i)];
    std::vector<bool>& flags = shared[static_cast<size_t>(i)];
    flags.resize(p.keys.size());
    for (size_t k = 0; k < p.keys.size(); ++k) flags[k] = on_boundary(p.region, edge_key_sum(p.keys[k], side));
  });
  size_t vertices = 0, triangles = 0, boundary = 0;
  for (size_t i = 0; i < parts.size(); ++i) {
    vertices += parts[i].mesh.positions.size(), triangles += parts[i].mesh.triangles.size();
    for (bool b : shared[i]) boundary += b;
  }
  Mesh out;
  // Reserved pages that are never written cost no memory.
  const auto room = [room_to_clip](size_t n) { return room_to_clip ? n + n / 32 + 1024 : n; };
  out.positions.reserve(room(vertices));
  out.triangles.reserve(room(triangles));
  EdgeVertexMap map(boundary);
  std::vector<uint32_t> remap;
  for (size_t i = 0; i < parts.size(); ++i) {
    PartMesh& p = parts[i];
    remap.resize(p.keys.size());
    for (size_t k = 0; k < p.keys.size(); ++k) {
      const auto fresh = static_cast<uint32_t>(out.positions.size());
      const uint32_t found = shared[i][k] ? map.find_or_insert(p.keys[k], fresh) : EdgeVertexMap::kAbsent;
      remap[k] = found == EdgeVertexMap::kAbsent ? fresh : found;
      if (found == EdgeVertexMap::kAbsent) out.positions.push_back(p.mesh.positions[k]);
    }
    for (const auto& t : p.mesh.triangles) out.triangles.push_back({remap[t[0]], remap[t[1]], remap[t[2]]});
    p.mesh = Mesh{};
    p.keys = {};
    shared[i] = {};
  }
  return out;
}

}  // namespace isotope
