#include "engine/extract/block_march.h"

#include <bit>

#include "engine/core/lending_pool.h"
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
    int points = 0;  // cut edges: 0, 3 or 4
    // Each cut edge as two cell corners, in cut's order, the edge's first node in grid order
    // first: a corner's number dx | dy << 1 | dz << 2 orders the corners as the grid does.
    std::array<std::array<uint8_t, 2>, 4> edge{};
    std::array<uint8_t, 3> triangle{};  // 3 points: the triangle over them, wound
    // 4 points: the one whose edge has the smallest key, where the quadrilateral is split. The
    // keys order the edges' p + q by bricks of 16 doubled coordinates first, so the order of a
    // cell's edges depends on which of its axes end on a brick's far face (bit a: axis a does,
    // the cell's lowest corner is 7 modulo 8 along it), and on nothing else.
    std::array<uint8_t, 8> quad_first{};
  };
  std::array<uint8_t, 4> corner{};  // offsets dx | dy << 1 | dz << 2 from the cell's lowest corner
  bool positive = false;            // its orientation
  std::array<Case, 16> cases{};     // by sign case: bit i set where corner i is above the isovalue
};
// What a sign case of a cell's corners cuts: the cell's cut edges, each once, in the order the
// walk of its tetrahedra first meets them (which is the order their vertices are made in), and
// the tetrahedra cut, in their order, each as its number among the cell's six with its own sign
// case shifted by 3, and its points as indices into the cell's edges. A cut edge is shared by
// two of a cut cell's tetrahedra on average, so looking each up once halves the lookups; and most
// of a cut cell's tetrahedra are not cut, which the list skips without a branch each.
struct CellCut {
  uint8_t edges = 0;
  uint8_t tets = 0;
  std::array<uint8_t, 19> edge{};  // a | b << 3 for the edge between corners a < b
  std::array<uint8_t, 6> tet{};
  std::array<std::array<uint8_t, 4>, 6> point{};
};
struct CellTables {
  std::array<std::array<CellTet, 6>, 8> tets;    // by parity
  std::array<std::array<CellCut, 256>, 8> cuts;  // by parity, then the cell's sign case
};

// A corner's offset along each axis.
constexpr int64_t dx(int corner) { return corner & 1; }
constexpr int64_t dy(int corner) { return (corner >> 1) & 1; }
constexpr int64_t dz(int corner) { return corner >> 2; }

CellTables make_cell_tables() {
  const TetCutter cutter(0.5f, 4, {0, 0, 0}, {1, 1, 1});  // values 0 and 1 give every sign case
  // Large enough that a cell may end on a key brick's face along any axis.
  const TetCutter keys(0.5f, 64, {0, 0, 0}, {1, 1, 1});
  CellTables out;
  for (size_t p = 0; p < 8; ++p) {
    const Coord cell{static_cast<int64_t>(p & 1), static_cast<int64_t>((p >> 1) & 1), static_cast<int64_t>(p >> 2)};
    const std::array<Tet, 6> tets = cell_tetrahedra(cell);
    for (size_t t = 0; t < 6; ++t) {
      CellTet& tet = out.tets[p][t];
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
        for (size_t i = 0; i < static_cast<size_t>(cut.points); ++i) {
          const uint8_t a = tet.corner[static_cast<size_t>(cut.edges[i][0])];
          const uint8_t b = tet.corner[static_cast<size_t>(cut.edges[i][1])];
          c.edge[i] = {std::min(a, b), std::max(a, b)};
        }
        if (cut.points == 3)
          for (size_t i = 0; i < 3; ++i) c.triangle[i] = static_cast<uint8_t>(cut.triangle[0][i]);
        if (cut.points != 4) continue;
        for (size_t far = 0; far < 8; ++far) {
          // A cell of this parity whose lowest corner is 7 modulo 8 along the axes of FAR: none
          // where the parity is even along one of them.
          if ((far & ~p) != 0) continue;
          Coord o{};
          for (size_t a = 0; a < 3; ++a) o[a] = (far >> a) & 1 ? 7 : (p >> a) & 1;
          uint64_t least = 0;
          for (size_t i = 0; i < 4; ++i) {
            const int a = c.edge[i][0], b = c.edge[i][1];
            const uint64_t key =
                keys.edge_key_of_sum(2 * o[0] + dx(a) + dx(b), 2 * o[1] + dy(a) + dy(b), 2 * o[2] + dz(a) + dz(b));
            if (i == 0 || key < least) least = key, c.quad_first[far] = static_cast<uint8_t>(i);
          }
        }
      }
    }
    for (unsigned above = 0; above < 256; ++above) {
      CellCut& cut_of = out.cuts[p][above];
      for (size_t t = 0; t < 6; ++t) {
        unsigned k = 0;
        for (size_t i = 0; i < 4; ++i) k |= ((above >> out.tets[p][t].corner[i]) & 1) << i;
        const CellTet::Case& cut = out.tets[p][t].cases[k];
        if (cut.points == 0) continue;
        for (size_t i = 0; i < static_cast<size_t>(cut.points); ++i) {
          const auto pair = static_cast<uint8_t>(cut.edge[i][0] | cut.edge[i][1] << 3);
          size_t e = 0;
          while (e < cut_of.edges && cut_of.edge[e] != pair) ++e;
          if (e == cut_of.edges) cut_of.edge[cut_of.edges++] = pair;
          cut_of.point[cut_of.tets][i] = static_cast<uint8_t>(e);
        }
        cut_of.tet[cut_of.tets++] = static_cast<uint8_t>(t | k << 3);
      }
    }
  }
  return out;
}

// Never destroyed: an extraction may end at exit, and give its memo back then.
LendingPool<EdgeMemo>& edge_memos() {
  static auto* pool = new LendingPool<EdgeMemo>;
  return *pool;
}

}  // namespace

LentEdgeMemo::LentEdgeMemo() : memo_(edge_memos().take([] { return std::make_unique<EdgeMemo>(); })) {}
LentEdgeMemo::~LentEdgeMemo() { edge_memos().give(std::move(memo_)); }
void give_back_edge_memos() { edge_memos().clear(); }

void march_block(const float* f, int64_t stride, const Coord& base, const std::array<int64_t, 3>& cells, float iso,
                 EdgeMemo& memo, MeshBuilder& builder) {
  static const CellTables kTables = make_cell_tables();
  int64_t offset[8];  // each cell corner's value, from the cell's lowest corner's
  for (int k = 0; k < 8; ++k) offset[k] = (dz(k) * stride + dy(k)) * stride + dx(k);
  // The step from a cell's memo slot (its lowest corner doubled) to the slot of the edge between
  // two of its corners.
  const int64_t wyz = memo.width_yz();
  int64_t slot_step[8][8];
  for (int a = 0; a < 8; ++a)
    for (int b = 0; b < 8; ++b) slot_step[a][b] = ((dx(a) + dx(b)) * wyz + dz(a) + dz(b)) * wyz + dy(a) + dy(b);
  // The slot of the box's lowest corner, doubled: y and z from its row's and slab's lowest planes.
  uint64_t* const slots = memo.slots() + 2 * base[0] * wyz * wyz;
  const uint64_t stamp = memo.stamp();
  memo.marched(2 * base[0], 2 * (base[0] + cells[0]));
  // Each node's sign once, a row to a word, rather than each cell's eight corners from its values:
  // a row's cells that the isovalue cuts are then a few bit operations on four rows' words.
  const int64_t row_words = cells[1] + 1;
  uint32_t* const rows = memo.rows();
  for (int64_t z = 0; z <= cells[2]; ++z)
    for (int64_t y = 0; y <= cells[1]; ++y) {
      const float* row = f + (z * stride + y) * stride;
      uint32_t signs = 0;
      for (int64_t x = 0; x <= cells[0]; ++x) signs |= static_cast<uint32_t>(row[x] > iso) << x;
      rows[z * row_words + y] = signs;
    }
  const uint32_t row_cells = (uint32_t{1} << cells[0]) - 1;
  for (int64_t z = 0; z < cells[2]; ++z)
    for (int64_t y = 0; y < cells[1]; ++y) {
      const uint32_t r0 = rows[z * row_words + y], r1 = rows[z * row_words + y + 1];
      const uint32_t r2 = rows[(z + 1) * row_words + y], r3 = rows[(z + 1) * row_words + y + 1];
      const uint32_t all = r0 & r1 & r2 & r3, any = r0 | r1 | r2 | r3;
      // Cells with a corner above the isovalue and one not.
      uint32_t cut_cells = (any | any >> 1) & ~(all & all >> 1) & row_cells;
      while (cut_cells != 0) {
        const auto x = static_cast<int64_t>(std::countr_zero(cut_cells));
        cut_cells &= cut_cells - 1;
        // bit i: corner i is above the isovalue
        const unsigned above = (r0 >> x & 3) | (r1 >> x & 3) << 2 | (r2 >> x & 3) << 4 | (r3 >> x & 3) << 6;
        const float* c = f + (z * stride + y) * stride + x;
        const Coord o{base[0] + x, base[1] + y, base[2] + z};
        const size_t parity = static_cast<size_t>((o[0] & 1) | (o[1] & 1) << 1 | (o[2] & 1) << 2);
        const std::array<CellTet, 6>& tets = kTables.tets[parity];
        const CellCut& cell = kTables.cuts[parity][above];
        const size_t far = static_cast<size_t>((o[0] & 7) == 7) | static_cast<size_t>((o[1] & 7) == 7) << 1 |
                           static_cast<size_t>((o[2] & 7) == 7) << 2;
        const int64_t cell_slot = ((2 * x) * wyz + 2 * z) * wyz + 2 * y;
        uint32_t vertex[19];  // of each of the cell's cut edges
        for (size_t e = 0; e < cell.edges; ++e) {
          const int a = cell.edge[e] & 7, b = cell.edge[e] >> 3;
          uint64_t& slot = slots[cell_slot + slot_step[a][b]];
          if (slot >> 32 == stamp) {
            vertex[e] = static_cast<uint32_t>(slot);
            continue;
          }
          // Not made in this row of boxes yet (nor in the last one's highest plane): no other box
          // of the slab has it.
          const Coord p{o[0] + dx(a), o[1] + dy(a), o[2] + dz(a)}, q{o[0] + dx(b), o[1] + dy(b), o[2] + dz(b)};
          vertex[e] = builder.unwelded_vertex(p, c[offset[a]], q, c[offset[b]]);
          slot = stamp << 32 | vertex[e];
        }
        for (size_t t = 0; t < cell.tets; ++t) {
          const CellTet& tet = tets[cell.tet[t] & 7];
          const CellTet::Case& cut = tet.cases[cell.tet[t] >> 3];
          uint32_t v[4];
          for (size_t i = 0; i < 4; ++i) v[i] = vertex[cell.point[t][i]];
          if (cut.points == 3) {
            builder.add_triangle(v[cut.triangle[0]], v[cut.triangle[1]], v[cut.triangle[2]]);
            continue;
          }
          // A quadrilateral, split along the diagonal through its smallest edge key, as TetCutter::cut does.
          const size_t m = cut.quad_first[far];
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
}

}  // namespace isotope
