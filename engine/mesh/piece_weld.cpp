#include "engine/mesh/piece_weld.h"

#include <utility>

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
  const size_t n = parts.size();
  // Which vertices are shared candidates, per part, in parallel.
  std::vector<std::vector<uint32_t>> shared(n);
  parallel_for(int64_t{0}, static_cast<int64_t>(n), [&](int64_t i) {
    const PartMesh& p = parts[static_cast<size_t>(i)];
    std::vector<uint32_t>& candidates = shared[static_cast<size_t>(i)];
    for (size_t k = 0; k < p.keys.size(); ++k)
      if (on_boundary(p.region, edge_key_sum(p.keys[k], side))) candidates.push_back(static_cast<uint32_t>(k));
  });
  // In piece order, the candidates only: each either meets a vertex an earlier part made (a part
  // has welded its own), or takes the next index, which counting the vertices met so far gives.
  // What each part's vertices and triangles start at follows.
  size_t boundary = 0;
  for (const auto& c : shared) boundary += c.size();
  EdgeVertexMap map(boundary);
  std::vector<std::vector<std::pair<uint32_t, uint32_t>>> met(n);  // (vertex of the part, index made before)
  std::vector<size_t> first_vertex(n + 1, 0), first_triangle(n + 1, 0);
  for (size_t i = 0; i < n; ++i) {
    const PartMesh& p = parts[i];
    const size_t base = first_vertex[i];
    for (uint32_t k : shared[i]) {
      const auto fresh = static_cast<uint32_t>(base + k - met[i].size());
      const uint32_t found = map.find_or_insert(p.keys[k], fresh);
      if (found != EdgeVertexMap::kAbsent) met[i].push_back({k, found});
    }
    first_vertex[i + 1] = base + p.keys.size() - met[i].size();
    first_triangle[i + 1] = first_triangle[i] + p.mesh.triangles.size();
    shared[i] = {};
  }
  Mesh out;
  // Reserved pages that are never written cost no memory; resizing leaves the arrays unwritten
  // (Mesh::Array), so that the parts below touch their own pages, on their own threads.
  const auto room = [room_to_clip](size_t count) { return room_to_clip ? count + count / 32 + 1024 : count; };
  out.positions.reserve(room(first_vertex[n]));
  out.triangles.reserve(room(first_triangle[n]));
  out.positions.resize(first_vertex[n]);
  out.triangles.resize(first_triangle[n]);
  parallel_for(int64_t{0}, static_cast<int64_t>(n), [&](int64_t i) {
    PartMesh& p = parts[static_cast<size_t>(i)];
    const auto& meets = met[static_cast<size_t>(i)];
    std::vector<uint32_t> remap(p.keys.size());
    size_t m = 0;
    auto to = first_vertex[static_cast<size_t>(i)];
    // This part's stretches of the arrays, faulted in at once rather than a page at a time
    detail::prefault(out.positions.data() + to,
                     (first_vertex[static_cast<size_t>(i) + 1] - to) * sizeof(out.positions[0]));
    detail::prefault(out.triangles.data() + first_triangle[static_cast<size_t>(i)],
                     p.mesh.triangles.size() * sizeof(out.triangles[0]));
    for (size_t k = 0; k < remap.size(); ++k) {
      if (m < meets.size() && meets[m].first == k) {
        remap[k] = meets[m++].second;
        continue;
      }
      remap[k] = static_cast<uint32_t>(to);
      out.positions[to++] = p.mesh.positions[k];
    }
    auto t = first_triangle[static_cast<size_t>(i)];
    for (const auto& tri : p.mesh.triangles) out.triangles[t++] = {remap[tri[0]], remap[tri[1]], remap[tri[2]]};
    p.mesh = Mesh{};
    p.keys = {};
  });
  return out;
}

}  // namespace isotope
