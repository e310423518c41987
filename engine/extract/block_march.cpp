#include "engine/extract/block_march.h"

#include "engine/extract/traversal.h"
#include "engine/hierarchy/kuhn.h"

namespace isotope {
namespace {

// A cell's six tetrahedra depend on its parity only (which corner is all even): corners as
// offsets (dx | dy << 1 | dz << 2) from the cell's lowest corner, and their orientation.
struct ParityTets {
  std::array<std::array<int, 4>, 6> corner{};
  std::array<bool, 6> positive{};
};

std::array<ParityTets, 8> make_parity_tets() {
  std::array<ParityTets, 8> out;
  for (int p = 0; p < 8; ++p) {
    const Coord cell{p & 1, (p >> 1) & 1, (p >> 2) & 1};
    const std::array<Tet, 6> tets = cell_tetrahedra(cell);
    for (size_t t = 0; t < 6; ++t) {
      for (size_t i = 0; i < 4; ++i) {
        const Coord& c = tets[t][i];
        out[static_cast<size_t>(p)].corner[t][i] =
            static_cast<int>((c[0] - cell[0]) | (c[1] - cell[1]) << 1 | (c[2] - cell[2]) << 2);
      }
      out[static_cast<size_t>(p)].positive[t] = traversal::orientation(tets[t]) > 0;
    }
  }
  return out;
}

}  // namespace

void march_block(const float* f, int64_t stride, const Coord& base, const std::array<int64_t, 3>& cells, float iso,
                 EdgeMemo& memo, MeshBuilder& builder) {
  static const std::array<ParityTets, 8> kTets = make_parity_tets();
  const int64_t offset[8] = {0,
                             1,
                             stride,
                             stride + 1,
                             stride * stride,
                             stride * stride + 1,
                             stride * stride + stride,
                             stride * stride + stride + 1};
  memo.start(base, cells);
  for (int64_t z = 0; z < cells[2]; ++z)
    for (int64_t y = 0; y < cells[1]; ++y)
      for (int64_t x = 0; x < cells[0]; ++x) {
        const float* c = f + (z * stride + y) * stride + x;
        unsigned above = 0;  // bit i: corner i (dx | dy << 1 | dz << 2) is inside
        for (int i = 0; i < 8; ++i) above |= static_cast<unsigned>(c[offset[i]] > iso) << i;
        if (above == 0 || above == 0xff) continue;
        const Coord o{base[0] + x, base[1] + y, base[2] + z};
        const ParityTets& p = kTets[static_cast<size_t>((o[0] & 1) | (o[1] & 1) << 1 | (o[2] & 1) << 2)];
        for (size_t t = 0; t < 6; ++t) {
          // Most of a cut cell's tetrahedra are not cut: skip them before building their corners.
          unsigned in = 0;
          for (size_t i = 0; i < 4; ++i) in += (above >> p.corner[t][i]) & 1;
          if (in == 0 || in == 4) continue;
          Tet corners;
          std::array<float, 4> values;
          for (size_t i = 0; i < 4; ++i) {
            const int k = p.corner[t][i];
            corners[i] = {o[0] + (k & 1), o[1] + ((k >> 1) & 1), o[2] + (k >> 2)};
            values[i] = c[offset[k]];
          }
          builder.add_tet(corners, values, p.positive[t], &memo);
        }
      }
}

}  // namespace isotope
