#include "engine/extract/block_march.h"

#include "engine/extract/traversal.h"
#include "engine/hierarchy/kuhn.h"

namespace isotope {
namespace {

// One of a cell's six tetrahedra, which depend on the cell's parity only (which corner is all
// even), with what marching tetrahedra makes of each of its sign cases. Built once from
// TetCutter::cut, so that the kernel cuts as MeshBuilder::add_tet does, without building the
// corners' coordinates of every tetrahedron it looks at.
struct CellTet {
  struct Case {
    int points = 0;                                // cut edges: 0, 3 or 4
    std::array<std::array<uint8_t, 2>, 4> edge{};  // each as two cell corners, in cut's order
    std::array<uint8_t, 3> triangle{};             // 3 points: the triangle over them, wound
  };
  std::array<uint8_t, 4> corner{};  // offsets dx | dy << 1 | dz << 2 from the cell's lowest corner
  bool positive = false;            // its orientation
  std::array<Case, 16> cases{};     // by sign case: bit i set where corner i is above the isovalue
};
using ParityTets = std::array<std::array<CellTet, 6>, 8>;

ParityTets make_parity_tets() {
  const TetCutter cutter(0.5f, 4, {0, 0, 0}, {1, 1, 1});  // values 0 and 1 give every sign case
  ParityTets out;
  for (size_t p = 0; p < 8; ++p) {
    const Coord cell{static_cast<int64_t>(p & 1), static_cast<int64_t>((p >> 1) & 1), static_cast<int64_t>(p >> 2)};
    const std::array<Tet, 6> tets = cell_tetrahedra(cell);
    for (size_t t = 0; t < 6; ++t) {
      CellTet& tet = out[p][t];
      for (size_t i = 0; i < 4; ++i) {
        const Coord& c = tets[t][i];
        tet.corner[i] = static_cast<uint8_t>((c[0] - cell[0]) | (c[1] - cell[1]) << 1 | (c[2] - cell[2]) << 2);
      }
      tet.positive = traversal::orientation(tets[t]) > 0;
      for (size_t k = 0; k < 16; ++k) {
        std::array<float, 4> values{};
        for (size_t i = 0; i < 4; ++i) values[i] = static_cast<float>((k >> i) & 1);
        const TetCutter::Cut cut = cutter.cut(tets[t], values, tet.positive);
        CellTet::Case& c = tet.cases[k];
        c.points = cut.points;
        for (size_t i = 0; i < static_cast<size_t>(cut.points); ++i)
          c.edge[i] = {tet.corner[static_cast<size_t>(cut.edges[i][0])],
                       tet.corner[static_cast<size_t>(cut.edges[i][1])]};
        if (cut.points == 3)
          for (size_t i = 0; i < 3; ++i) c.triangle[i] = static_cast<uint8_t>(cut.triangle[0][i]);
      }
    }
  }
  return out;
}

// A corner's offset along each axis.
constexpr int64_t dx(int corner) { return corner & 1; }
constexpr int64_t dy(int corner) { return (corner >> 1) & 1; }
constexpr int64_t dz(int corner) { return corner >> 2; }

}  // namespace

void march_block(const float* f, int64_t stride, const Coord& base, const std::array<int64_t, 3>& cells, float iso,
                 EdgeMemo& memo, MeshBuilder& builder) {
  static const ParityTets kTets = make_parity_tets();
  int64_t offset[8];  // each cell corner's value, from the cell's lowest corner's
  for (int k = 0; k < 8; ++k) offset[k] = (dz(k) * stride + dy(k)) * stride + dx(k);
  // The step from a cell's memo slot (its lowest corner doubled) to the slot of the edge between
  // two of its corners.
  const int64_t w = memo.width();
  int64_t slot_step[8][8];
  for (int a = 0; a < 8; ++a)
    for (int b = 0; b < 8; ++b) slot_step[a][b] = ((dz(a) + dz(b)) * w + dy(a) + dy(b)) * w + dx(a) + dx(b);
  memo.start();
  uint64_t* const slots = memo.slots();
  const uint64_t stamp = memo.stamp();
  const TetCutter& cutter = builder.cutter();
  for (int64_t z = 0; z < cells[2]; ++z)
    for (int64_t y = 0; y < cells[1]; ++y)
      for (int64_t x = 0; x < cells[0]; ++x) {
        const float* c = f + (z * stride + y) * stride + x;
        unsigned above = 0;  // bit i: corner i is above the isovalue
        for (int i = 0; i < 8; ++i) above |= static_cast<unsigned>(c[offset[i]] > iso) << i;
        if (above == 0 || above == 0xff) continue;
        const Coord o{base[0] + x, base[1] + y, base[2] + z};
        const std::array<CellTet, 6>& tets = kTets[static_cast<size_t>((o[0] & 1) | (o[1] & 1) << 1 | (o[2] & 1) << 2)];
        const int64_t cell_slot = ((2 * z) * w + 2 * y) * w + 2 * x;
        for (const CellTet& tet : tets) {
          unsigned k = 0;
          for (size_t i = 0; i < 4; ++i) k |= ((above >> tet.corner[i]) & 1) << i;
          const CellTet::Case& cut = tet.cases[k];
          if (cut.points == 0) continue;  // most of a cut cell's tetrahedra are not cut
          uint32_t v[4];
          for (size_t i = 0; i < static_cast<size_t>(cut.points); ++i) {
            const int a = cut.edge[i][0], b = cut.edge[i][1];
            uint64_t& slot = slots[cell_slot + slot_step[a][b]];
            if (slot >> 32 == stamp) {
              v[i] = static_cast<uint32_t>(slot);
              continue;
            }
            const Coord p{o[0] + dx(a), o[1] + dy(a), o[2] + dz(a)}, q{o[0] + dx(b), o[1] + dy(b), o[2] + dz(b)};
            const float fp = c[offset[a]], fq = c[offset[b]];
            // p + q from the box's doubled lowest corner: strictly inside the box, the edge belongs
            // to the box's cells alone, so no other box will ask for its vertex.
            const int64_t ex = 2 * x + dx(a) + dx(b), ey = 2 * y + dy(a) + dy(b), ez = 2 * z + dz(a) + dz(b);
            if (ex > 0 && ex < 2 * cells[0] && ey > 0 && ey < 2 * cells[1] && ez > 0 && ez < 2 * cells[2])
              v[i] = builder.unwelded_vertex(p, fp, q, fq);
            else
              v[i] = builder.welded_vertex(cutter.edge_key(p, q), p, fp, q, fq);
            slot = stamp << 32 | v[i];
          }
          if (cut.points == 3) {
            builder.add_triangle(v[cut.triangle[0]], v[cut.triangle[1]], v[cut.triangle[2]]);
            continue;
          }
          // A quadrilateral, split along the diagonal through its smallest edge key, as TetCutter::cut does.
          uint64_t keys[4];
          for (size_t i = 0; i < 4; ++i) {
            const int a = cut.edge[i][0], b = cut.edge[i][1];
            keys[i] =
                cutter.edge_key_of_sum(2 * o[0] + dx(a) + dx(b), 2 * o[1] + dy(a) + dy(b), 2 * o[2] + dz(a) + dz(b));
          }
          size_t m = 0;
          for (size_t i = 1; i < 4; ++i)
            if (keys[i] < keys[m]) m = i;
          const uint32_t v0 = v[m], v1 = v[(m + 1) & 3], v2 = v[(m + 2) & 3], v3 = v[(m + 3) & 3];
          if (tet.positive) {
            builder.add_triangle(v0, v1, v2);
            builder.add_triangle(v0, v2, v3);
          } else {
            builder.add_triangle(v0, v2, v1);
            builder.add_triangle(v0, v3, v2);
          }
        }
      }
}

}  // namespace isotope
