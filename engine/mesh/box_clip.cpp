#include "engine/mesh/box_clip.h"

#include <algorithm>
#include <unordered_map>
#include <utility>
#include <vector>

namespace isotope {
namespace {

using Point = BoxClip::Point;

// Where the edge from `in` (at or before the face) to `out` (past it) meets the face of `axis`:
// from the inside corner, whichever triangle asks.
Point crossing(const Point& in, const Point& out, int axis, float face) {
  const double t = (static_cast<double>(face) - in[axis]) / (static_cast<double>(out[axis]) - in[axis]);
  Point p;
  for (int a = 0; a < 3; ++a)
    p[a] =
        a == axis ? face : static_cast<float>(static_cast<double>(in[a]) + t * (static_cast<double>(out[a]) - in[a]));
  return p;
}

// The clip of one triangle, over corners of any kind V with a position (pos(v)); cross(in, out,
// axis) makes the corner where an edge meets a face, emit(a, b, c) takes each triangle left.
template <class V, class Pos, class Cross, class Emit>
void clip_triangle(const BoxClip& box, const V& a, const V& b, const V& c, const Pos& pos, const Cross& cross,
                   const Emit& emit) {
  // At most 2 pieces per face: 1, 2, 4, 8.
  std::array<std::array<V, 3>, 8> pieces, next;
  pieces[0] = {a, b, c};
  int n = 1;
  for (int axis = 0; axis < 3; ++axis) {
    if (!box.active[static_cast<size_t>(axis)]) continue;
    const float face = box.face[static_cast<size_t>(axis)];
    int m = 0;
    for (int i = 0; i < n; ++i) {
      const auto& t = pieces[static_cast<size_t>(i)];
      bool in[3];
      for (int k = 0; k < 3; ++k) in[k] = pos(t[static_cast<size_t>(k)])[static_cast<size_t>(axis)] <= face;
      if (in[0] && in[1] && in[2]) {
        next[static_cast<size_t>(m++)] = t;
        continue;
      }
      // The polygon left, in the triangle's order: its corners inside, and a crossing on each
      // edge that leaves, unless the inside corner lies on the face (then it is the crossing).
      std::array<V, 4> poly;
      int k = 0;
      for (int i0 = 0; i0 < 3; ++i0) {
        const int i1 = (i0 + 1) % 3;
        const V& p = t[static_cast<size_t>(i0)];
        const V& q = t[static_cast<size_t>(i1)];
        if (in[i0]) poly[static_cast<size_t>(k++)] = p;
        if (in[i0] == in[i1]) continue;
        const V& inside = in[i0] ? p : q;
        const V& outside = in[i0] ? q : p;
        if (pos(inside)[static_cast<size_t>(axis)] < face)
          poly[static_cast<size_t>(k++)] = cross(inside, outside, axis);
      }
      for (int j = 1; j + 1 < k; ++j)
        next[static_cast<size_t>(m++)] = {poly[0], poly[static_cast<size_t>(j)], poly[static_cast<size_t>(j) + 1]};
    }
    std::swap(pieces, next);
    n = m;
  }
  for (int i = 0; i < n; ++i) {
    const auto& t = pieces[static_cast<size_t>(i)];
    emit(t[0], t[1], t[2]);
  }
}

bool reaches_past(const BoxClip& box, const Point& p) {
  for (int a = 0; a < 3; ++a)
    if (box.active[static_cast<size_t>(a)] && p[static_cast<size_t>(a)] > box.face[static_cast<size_t>(a)]) return true;
  return false;
}

}  // namespace

BoxClip BoxClip::of(const std::array<int64_t, 3>& dims, int64_t n, const std::array<double, 3>& origin,
                    const std::array<double, 3>& spacing) {
  BoxClip box;
  for (size_t a = 0; a < 3; ++a) {
    // As TetCutter::point places a vertex at a node of coordinate dims - 1.
    box.face[a] = static_cast<float>(origin[a] + spacing[a] * static_cast<double>(dims[a] - 1));
    box.active[a] = dims[a] - 1 < n;
  }
  return box;
}

int clipped_triangles(const BoxClip& box, const Point& a, const Point& b, const Point& c) {
  if (!reaches_past(box, a) && !reaches_past(box, b) && !reaches_past(box, c)) return 1;
  int count = 0;
  clip_triangle(
      box, a, b, c, [](const Point& p) -> const Point& { return p; },
      [&](const Point& in, const Point& out, int axis) {
        return crossing(in, out, axis, box.face[static_cast<size_t>(axis)]);
      },
      [&](const Point&, const Point&, const Point&) { ++count; });
  return count;
}

int clipped_triangles(const BoxClip& box, const TetCutter& cutter, const std::array<Coord, 4>& corners,
                      const std::array<float, 4>& values, bool positive) {
  const TetCutter::Cut cut = cutter.cut(corners, values, positive);
  std::array<Point, 4> p;
  for (int i = 0; i < cut.points; ++i) {
    const auto [a, b] = cut.edges[static_cast<size_t>(i)];
    p[static_cast<size_t>(i)] = cutter.point(corners[static_cast<size_t>(a)], values[static_cast<size_t>(a)],
                                             corners[static_cast<size_t>(b)], values[static_cast<size_t>(b)]);
  }
  int count = 0;
  for (int i = 0; i < cut.triangles; ++i) {
    const auto& t = cut.triangle[static_cast<size_t>(i)];
    count += clipped_triangles(box, p[static_cast<size_t>(t[0])], p[static_cast<size_t>(t[1])],
                               p[static_cast<size_t>(t[2])]);
  }
  return count;
}

int64_t clipped_triangles(const Mesh& mesh, const BoxClip& box) {
  if (!box.any()) return static_cast<int64_t>(mesh.triangles.size());
  int64_t count = 0;
  for (const auto& t : mesh.triangles)
    count += clipped_triangles(box, mesh.positions[t[0]], mesh.positions[t[1]], mesh.positions[t[2]]);
  return count;
}

void clip_to_box(Mesh& mesh, const BoxClip& box) {
  if (!box.any()) return;
  const size_t vertices = mesh.positions.size();
  std::vector<bool> past(vertices);
  bool any = false;
  for (size_t v = 0; v < vertices; ++v) any |= past[v] = reaches_past(box, mesh.positions[v]);
  if (!any) return;
  // The crossings made so far, by the edge's inside and outside vertex and the face's axis.
  std::array<std::unordered_map<uint64_t, uint32_t>, 3> made;
  auto pos = [&](uint32_t v) -> Point { return mesh.positions[v]; };
  auto cross = [&](uint32_t in, uint32_t out, int axis) {
    const uint64_t key = uint64_t{in} << 32 | out;
    auto [it, fresh] = made[static_cast<size_t>(axis)].try_emplace(key, static_cast<uint32_t>(mesh.positions.size()));
    if (fresh)
      mesh.positions.push_back(
          crossing(mesh.positions[in], mesh.positions[out], axis, box.face[static_cast<size_t>(axis)]));
    return it->second;
  };
  // In place, in order: triangle r is read before slot r is written; what a clipped triangle
  // adds beyond the slots read so far waits in `waiting` (a few, from the few triangles clipped),
  // so that a mesh of hundreds of megabytes is not copied for them.
  auto& triangles = mesh.triangles;
  const size_t n = triangles.size();
  std::vector<std::array<uint32_t, 3>> waiting;
  size_t first_waiting = 0, w = 0;
  auto put = [&](const std::array<uint32_t, 3>& t, size_t read) {
    if (first_waiting == waiting.size() && w <= read) {
      triangles[w++] = t;
      return;
    }
    waiting.push_back(t);
  };
  for (size_t r = 0; r < n; ++r) {
    const std::array<uint32_t, 3> t = triangles[r];
    if (!past[t[0]] && !past[t[1]] && !past[t[2]]) {
      put(t, r);
    } else {
      clip_triangle(box, t[0], t[1], t[2], pos, cross, [&](uint32_t x, uint32_t y, uint32_t z) { put({x, y, z}, r); });
    }
    while (first_waiting < waiting.size() && w <= r) triangles[w++] = waiting[first_waiting++];
    if (first_waiting == waiting.size()) waiting.clear(), first_waiting = 0;
  }
  triangles.resize(w);
  triangles.insert(triangles.end(), waiting.begin() + static_cast<std::ptrdiff_t>(first_waiting), waiting.end());
  // Drop the vertices left without a triangle (those past the box, and any whose every triangle
  // was clipped away), keeping the order of the rest.
  std::vector<uint32_t> index(mesh.positions.size(), 0);
  for (const auto& t : mesh.triangles)
    for (uint32_t v : t) index[v] = 1;
  uint32_t kept = 0;
  for (size_t v = 0; v < index.size(); ++v) {
    if (!index[v]) continue;
    mesh.positions[kept] = mesh.positions[v];
    index[v] = kept++;
  }
  mesh.positions.resize(kept);
  for (auto& t : mesh.triangles)
    for (uint32_t& v : t) v = index[v];
}

}  // namespace isotope
