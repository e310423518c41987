#include "engine/mesh/box_clip.h"

#include <algorithm>
#include <atomic>
#include <unordered_map>
#include <utility>
#include <vector>

#include "engine/core/parallel.h"

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

void clip_to_box(Mesh& mesh, const BoxClip& box) { clip_to_box(mesh, box, size_t{1} << 16); }

void clip_to_box(Mesh& mesh, const BoxClip& box, size_t block) {
  if (!box.any()) return;
  auto& triangles = mesh.triangles;
  const size_t n = triangles.size();
  // Blocks of triangles or vertices, for the passes that run in parallel.
  const size_t per_block = std::max<size_t>(block, 1);
  const auto blocks_of = [per_block](size_t count) { return (count + per_block - 1) / per_block; };
  const auto block_end = [per_block](size_t b, size_t count) { return std::min(count, (b + 1) * per_block); };
  const size_t vertices = mesh.positions.size();
  std::vector<uint8_t> past(vertices);
  std::atomic<bool> any{false};
  parallel_for(int64_t{0}, static_cast<int64_t>(blocks_of(vertices)), [&](int64_t i) {
    const auto b = static_cast<size_t>(i);
    bool mine = false;
    for (size_t v = b * per_block; v < block_end(b, vertices); ++v)
      mine |= (past[v] = reaches_past(box, mesh.positions[v])) != 0;
    if (mine) any.store(true, std::memory_order_relaxed);
  });
  if (!any.load()) return;
  // The triangles that reach past the box, a few along its far faces: found per block in parallel,
  // then clipped in order, so that the crossings are made in the order one pass over the triangles
  // meets them.
  const size_t blocks = blocks_of(n);
  std::vector<std::vector<size_t>> reaching(blocks);
  parallel_for(int64_t{0}, static_cast<int64_t>(blocks), [&](int64_t i) {
    const auto b = static_cast<size_t>(i);
    for (size_t r = b * per_block; r < block_end(b, n); ++r) {
      const auto& t = triangles[r];
      if (past[t[0]] | past[t[1]] | past[t[2]]) reaching[b].push_back(r);
    }
  });
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
  std::vector<size_t> first_row(blocks + 1);  // each block's first clipped triangle, counted over all
  std::vector<std::array<uint32_t, 3>> left;  // what they became, in order
  std::vector<size_t> first_left{0};          // each clipped triangle's first in `left`
  std::vector<size_t> kept(blocks);           // triangles each block ends with
  for (size_t b = 0; b < blocks; ++b) {
    first_row[b + 1] = first_row[b] + reaching[b].size();
    const size_t left_before = left.size();
    for (size_t r : reaching[b]) {
      const auto t = triangles[r];
      clip_triangle(box, t[0], t[1], t[2], pos, cross, [&](uint32_t x, uint32_t y, uint32_t z) {
        left.push_back({x, y, z});
      });
      first_left.push_back(left.size());
    }
    kept[b] = block_end(b, n) - b * per_block - reaching[b].size() + (left.size() - left_before);
  }
  // Where each block goes, and the memory for those that grow, taken before any block changes, so
  // that running out of it leaves the mesh as it was.
  std::vector<size_t> to(blocks + 1, 0);
  for (size_t b = 0; b < blocks; ++b) to[b + 1] = to[b] + kept[b];
  std::vector<std::vector<std::array<uint32_t, 3>>> grown(blocks);
  for (size_t b = 0; b < blocks; ++b)
    if (kept[b] > block_end(b, n) - b * per_block) grown[b].resize(kept[b]);
  if (to[blocks] > n) triangles.resize(to[blocks]);
  // What each block becomes: those with a clipped triangle are rebuilt from a copy of themselves,
  // in place when they do not grow (what lies past the box is mostly dropped), else beside.
  parallel_for(int64_t{0}, static_cast<int64_t>(blocks), [&](int64_t i) {
    const auto b = static_cast<size_t>(i);
    const std::vector<size_t>& rows = reaching[b];
    if (rows.empty()) return;
    const auto begin = triangles.begin() + static_cast<std::ptrdiff_t>(b * per_block);
    const auto end = triangles.begin() + static_cast<std::ptrdiff_t>(block_end(b, n));
    const std::vector<std::array<uint32_t, 3>> copy(begin, end);
    std::array<uint32_t, 3>* out = grown[b].empty() ? triangles.data() + b * per_block : grown[b].data();
    size_t j = 0;  // of rows
    for (size_t k = 0; k < copy.size(); ++k) {
      if (j < rows.size() && rows[j] == b * per_block + k) {
        const size_t c = first_row[b] + j++;
        out = std::copy(left.begin() + static_cast<std::ptrdiff_t>(first_left[c]),
                        left.begin() + static_cast<std::ptrdiff_t>(first_left[c + 1]), out);
      } else {
        *out++ = copy[k];
      }
    }
  });
  // The blocks slid to their places, serially: those moving up first, from the last, then the
  // others from the first, so that no block is overwritten before it moved (the places keep the
  // blocks' order).
  auto move = [&](size_t b) {
    const auto dest = triangles.begin() + static_cast<std::ptrdiff_t>(to[b]);
    const auto count = static_cast<std::ptrdiff_t>(kept[b]);
    if (!grown[b].empty()) {
      std::copy(grown[b].begin(), grown[b].end(), dest);
      grown[b] = {};
      return;
    }
    const auto from = triangles.begin() + static_cast<std::ptrdiff_t>(b * per_block);
    if (to[b] > b * per_block)
      std::copy_backward(from, from + count, dest + count);
    else if (to[b] < b * per_block)
      std::copy(from, from + count, dest);
  };
  for (size_t b = blocks; b-- > 0;)
    if (to[b] > b * per_block) move(b);
  for (size_t b = 0; b < blocks; ++b)
    if (to[b] <= b * per_block) move(b);
  triangles.resize(to[blocks]);
  // Drop the vertices left without a triangle (those past the box, and any whose every triangle
  // was clipped away), keeping the order of the rest.
  const size_t all = mesh.positions.size();
  std::vector<uint8_t> used(all, 0);
  parallel_for(int64_t{0}, static_cast<int64_t>(blocks_of(triangles.size())), [&](int64_t i) {
    const auto b = static_cast<size_t>(i);
    for (size_t r = b * per_block; r < block_end(b, triangles.size()); ++r)
      for (uint32_t v : triangles[r]) std::atomic_ref<uint8_t>(used[v]).store(1, std::memory_order_relaxed);
  });
  std::vector<uint32_t> first_kept(blocks_of(all) + 1, 0);
  parallel_for(int64_t{0}, static_cast<int64_t>(blocks_of(all)), [&](int64_t i) {
    const auto b = static_cast<size_t>(i);
    first_kept[b + 1] =
        static_cast<uint32_t>(std::count(used.begin() + static_cast<std::ptrdiff_t>(b * per_block),
                                         used.begin() + static_cast<std::ptrdiff_t>(block_end(b, all)), 1));
  });
  for (size_t b = 0; b < blocks_of(all); ++b) first_kept[b + 1] += first_kept[b];
  std::vector<uint32_t> index(all);
  parallel_for(int64_t{0}, static_cast<int64_t>(blocks_of(all)), [&](int64_t i) {
    const auto b = static_cast<size_t>(i);
    uint32_t k = first_kept[b];
    for (size_t v = b * per_block; v < block_end(b, all); ++v) index[v] = used[v] ? k++ : 0;
  });
  for (size_t v = 0; v < all; ++v)
    if (used[v]) mesh.positions[index[v]] = mesh.positions[v];
  mesh.positions.resize(first_kept.back());
  parallel_for(int64_t{0}, static_cast<int64_t>(blocks_of(triangles.size())), [&](int64_t i) {
    const auto b = static_cast<size_t>(i);
    for (size_t r = b * per_block; r < block_end(b, triangles.size()); ++r)
      for (uint32_t& v : triangles[r]) v = index[v];
  });
}

}  // namespace isotope
