#include "engine/mesh/marching_tetrahedra.h"

#include <utility>

namespace isotope {
namespace {

// One case of the table: the polygon's corners as tetrahedron edges (pairs of corner indices),
// in counter-clockwise order seen from the outside for a positively oriented tetrahedron.
struct Case {
  int count = 0;  // 0, 3 (triangle) or 4 (quadrilateral)
  std::array<std::array<int, 2>, 4> edges{};
};

using Vec = std::array<double, 3>;

Vec sub(const Vec& a, const Vec& b) { return {a[0] - b[0], a[1] - b[1], a[2] - b[2]}; }
Vec cross(const Vec& a, const Vec& b) {
  return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
}
double dot(const Vec& a, const Vec& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }

// Generated from the definition rather than typed in: cut the edges whose ends differ, order
// the cut points around the section, and orient by the reference tetrahedron's geometry.
std::array<Case, 16> make_table() {
  static constexpr Vec kRef[4] = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}};  // det = +1
  std::array<Case, 16> table{};
  for (int c = 1; c < 15; ++c) {
    int in[4], out[4], ni = 0, no = 0;
    for (int i = 0; i < 4; ++i) ((c >> i) & 1 ? in[ni++] : out[no++]) = i;
    Case& k = table[static_cast<size_t>(c)];
    if (ni == 1 || no == 1) {
      const int lone = ni == 1 ? in[0] : out[0];
      int n = 0;
      for (int i = 0; i < 4; ++i)
        if (i != lone) k.edges[static_cast<size_t>(n++)] = {lone, i};
      k.count = 3;
    } else {  // in {i, j}, out {k, l}: cycle ik, il, jl, jk (consecutive points share a face)
      k.edges = {{{in[0], out[0]}, {in[0], out[1]}, {in[1], out[1]}, {in[1], out[0]}}};
      k.count = 4;
    }
    Vec p[4], cin{0, 0, 0}, cout{0, 0, 0};
    for (int i = 0; i < k.count; ++i)
      for (int a = 0; a < 3; ++a) p[i][a] = 0.5 * (kRef[k.edges[i][0]][a] + kRef[k.edges[i][1]][a]);
    for (int i = 0; i < ni; ++i)
      for (int a = 0; a < 3; ++a) cin[a] += kRef[in[i]][a] / ni;
    for (int i = 0; i < no; ++i)
      for (int a = 0; a < 3; ++a) cout[a] += kRef[out[i]][a] / no;
    if (dot(cross(sub(p[1], p[0]), sub(p[2], p[0])), sub(cout, cin)) < 0)
      std::swap(k.edges[1], k.edges[static_cast<size_t>(k.count - 1)]);
  }
  return table;
}

const std::array<Case, 16>& table() {
  static const std::array<Case, 16> t = make_table();
  return t;
}

}  // namespace

TetCutter::TetCutter(float iso, int64_t side, const std::array<double, 3>& origin, const std::array<double, 3>& spacing)
    : iso_(iso), key_bricks_((2 * side - 1 + 15) / 16), origin_(origin), spacing_(spacing) {}

TetCutter::Cut TetCutter::cut(const std::array<Coord, 4>& corners, const std::array<float, 4>& values,
                              bool positive) const {
  int c = 0;
  for (int i = 0; i < 4; ++i) c |= (values[i] > iso_ ? 1 : 0) << i;
  const Case& k = table()[static_cast<size_t>(c)];
  Cut out;
  if (k.count == 0) return out;
  out.points = k.count;
  out.edges = k.edges;
  // Seen from the outside, counter-clockwise: the table's order for a positive tetrahedron.
  auto add = [&](int x, int y, int z) {
    if (!positive) std::swap(y, z);
    out.triangle[static_cast<size_t>(out.triangles++)] = {x, y, z};
  };
  if (k.count == 3) {
    add(0, 1, 2);
    return out;
  }
  // Split along the diagonal through the smallest edge key: it depends on the grid edges only,
  // not on the corner order or on which tetrahedron welded a vertex first.
  uint64_t keys[4];
  for (int i = 0; i < 4; ++i) keys[i] = edge_key(corners[k.edges[i][0]], corners[k.edges[i][1]]);
  int m = 0;
  for (int i = 1; i < 4; ++i)
    if (keys[i] < keys[m]) m = i;
  add(m, (m + 1) & 3, (m + 2) & 3);
  add(m, (m + 2) & 3, (m + 3) & 3);
  return out;
}

MeshBuilder::MeshBuilder(float iso, int64_t side, const std::array<double, 3>& origin,
                         const std::array<double, 3>& spacing, EdgeVertexMap* welds)
    : cutter_(iso, side, origin, spacing), own_map_(welds ? 0 : 64) {
  if (welds) {
    welds->clear();
    map_ = welds;
  }
}

Coord edge_key_sum(uint64_t key, int64_t side) {
  const int64_t bricks = (2 * side - 1 + 15) / 16;
  const auto brick = static_cast<int64_t>(key >> 12);
  const int64_t bx = brick % bricks, by = brick / bricks % bricks, bz = brick / (bricks * bricks);
  return {bx << 4 | static_cast<int64_t>(key & 15), by << 4 | static_cast<int64_t>(key >> 4 & 15),
          bz << 4 | static_cast<int64_t>(key >> 8 & 15)};
}

void MeshBuilder::keep_key(uint32_t fresh, uint64_t key, const Coord& p, const Coord& q) {
  const int64_t z2 = p[2] + q[2];
  // The two planes differ (a slab is a cell layer thick at least), so the vertex is on one at most.
  const int plane = z2 == plane_z2_[0] ? 0 : z2 == plane_z2_[1] ? 1 : -1;
  if (key == 0) key = cutter_.edge_key(p, q);
  if (keep_keys_) {
    detail::grow_prefaulted(keys_);
    keys_.push_back(key);
  }
  if (plane >= 0) plane_keys_[static_cast<size_t>(plane)].push_back({fresh, key});
}

void MeshBuilder::add_tet(const std::array<Coord, 4>& corners, const std::array<float, 4>& values, bool positive) {
  const TetCutter::Cut k = cutter_.cut(corners, values, positive);
  if (k.points == 0) return;
  uint32_t v[4];
  for (int i = 0; i < k.points; ++i) {
    const int a = k.edges[static_cast<size_t>(i)][0], b = k.edges[static_cast<size_t>(i)][1];
    v[i] = vertex(cutter_.edge_key(corners[a], corners[b]), corners[a], values[a], corners[b], values[b]);
  }
  for (int t = 0; t < k.triangles; ++t) {
    const auto& tri = k.triangle[static_cast<size_t>(t)];
    detail::grow_prefaulted(mesh_.triangles);
    mesh_.triangles.push_back({v[tri[0]], v[tri[1]], v[tri[2]]});
  }
}

}  // namespace isotope
