#include "engine/extract/full_resolution.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <stdexcept>
#include <vector>

#include "isotope/error.h"

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

#include "engine/core/parallel.h"
#include "engine/extract/slab_march.h"
#include "engine/extract/traversal.h"
#include "engine/hierarchy/kuhn.h"
#include "engine/mesh/marching_tetrahedra.h"

namespace isotope {
namespace {

// Cells per slab: enough work to pay for a task, a welding table and a merge step, few enough
// that a 257^3 volume gives dozens of slabs to balance over the threads, and a 65^3 one a single
// slab (nothing to merge).
constexpr int64_t kSlabCells = int64_t{1} << 18;

// Marching tetrahedra over the cells of layers [z_begin, z_end), in the serial walk's order.
void march_layers(const Volume& volume, float iso, int64_t z_begin, int64_t z_end, MeshBuilder& builder) {
  const auto& d = volume.dims;
  const float* values = volume.data();  // once, not per value (Volume::at chooses where they are)
  const auto at = [&](int64_t x, int64_t y, int64_t z) { return values[volume.index(x, y, z)]; };
  for (int64_t z = z_begin; z < z_end; ++z)
    for (int64_t y = 0; y + 1 < d[1]; ++y)
      for (int64_t x = 0; x + 1 < d[0]; ++x) {
        int above = 0;
        for (int c = 0; c < 8; ++c) above += at(x + (c & 1), y + ((c >> 1) & 1), z + (c >> 2)) > iso;
        if (above == 0 || above == 8) continue;
        for (const Tet& t : cell_tetrahedra({x, y, z}))
          builder.add_tet(t,
                          {at(t[0][0], t[0][1], t[0][2]), at(t[1][0], t[1][1], t[1][2]), at(t[2][0], t[2][1], t[2][2]),
                           at(t[3][0], t[3][1], t[3][2])},
                          traversal::orientation(t) > 0);
      }
}

// Triangles of a cell by its parity (bit a: its lowest corner's coordinate a is odd) and sign case
// (bit x + 2y + 4z: node (x, y, z) of the cell lies above the isovalue), from the tetrahedra
// cell_tetrahedra() gives a cell of that parity, cut as marching tetrahedra cuts them.
using CellTriangles = std::array<uint8_t, 8 * 256>;  // [parity << 8 | signs]
CellTriangles make_cell_triangles() {
  CellTriangles table{};
  for (int parity = 0; parity < 8; ++parity) {
    const Coord cell{parity & 1, (parity >> 1) & 1, (parity >> 2) & 1};
    const std::array<Tet, 6> tets = cell_tetrahedra(cell);
    for (int signs = 0; signs < 256; ++signs) {
      int count = 0;
      for (const Tet& t : tets) {
        std::array<float, 4> f;
        for (size_t c = 0; c < 4; ++c) {
          const int x = static_cast<int>(t[c][0] - cell[0]), y = static_cast<int>(t[c][1] - cell[1]),
                    z = static_cast<int>(t[c][2] - cell[2]);
          f[c] = static_cast<float>((signs >> (x + 2 * y + 4 * z)) & 1);
        }
        count += traversal::triangles_of(f, 0.5f);
      }
      table[static_cast<size_t>(parity << 8 | signs)] = static_cast<uint8_t>(count);
    }
  }
  return table;
}

// out[i] = f[i] > iso for i < n. GCC leaves the float compare to byte scalar: sixteen at a time
// with SSE2, which every x86-64 has (with the column cases below, the count went from 3.1 ns a
// cell to 1.1-1.3 on one thread).
void node_signs(const float* f, size_t n, float iso, uint8_t* out) {
  size_t i = 0;
#if defined(__SSE2__)
  const __m128 level = _mm_set1_ps(iso);
  const __m128i one = _mm_set1_epi8(1);
  for (; i + 16 <= n; i += 16) {
    const __m128i a = _mm_castps_si128(_mm_cmpgt_ps(_mm_loadu_ps(f + i), level));
    const __m128i b = _mm_castps_si128(_mm_cmpgt_ps(_mm_loadu_ps(f + i + 4), level));
    const __m128i c = _mm_castps_si128(_mm_cmpgt_ps(_mm_loadu_ps(f + i + 8), level));
    const __m128i d = _mm_castps_si128(_mm_cmpgt_ps(_mm_loadu_ps(f + i + 12), level));
    const __m128i bytes = _mm_packs_epi16(_mm_packs_epi32(a, b), _mm_packs_epi32(c, d));  // 0 or -1 each
    _mm_storeu_si128(reinterpret_cast<__m128i*>(out + i), _mm_and_si128(bytes, one));
  }
#endif
  for (; i < n; ++i) out[i] = f[i] > iso;
}

// The sign case bits of a column of four nodes (x fixed; rows y and y + 1 of planes z and z + 1):
// bits 0, 2, 4, 6. A cell's case is its two columns', the second shifted by one.
void column_cases(const uint8_t* s00, const uint8_t* s10, const uint8_t* s01, const uint8_t* s11, size_t n,
                  uint8_t* out) {
  size_t x = 0;
#if defined(__SSE2__)
  const auto load = [](const uint8_t* p) { return _mm_loadu_si128(reinterpret_cast<const __m128i*>(p)); };
  for (; x + 16 <= n; x += 16) {
    // Bytes of 0 or 1: shifting 16-bit lanes moves each byte's bit within the byte.
    const __m128i v = _mm_or_si128(_mm_or_si128(load(s00 + x), _mm_slli_epi16(load(s10 + x), 2)),
                                   _mm_or_si128(_mm_slli_epi16(load(s01 + x), 4), _mm_slli_epi16(load(s11 + x), 6)));
    _mm_storeu_si128(reinterpret_cast<__m128i*>(out + x), v);
  }
#endif
  for (; x < n; ++x) out[x] = static_cast<uint8_t>(s00[x] | s10[x] << 2 | s01[x] << 4 | s11[x] << 6);
}

}  // namespace

int64_t count_full_resolution_triangles(const Volume& volume, float iso) {
  if (!std::isfinite(iso)) throw InvalidInput("the isovalue must be a finite number");
  static const CellTriangles table = make_cell_triangles();
  const auto& d = volume.dims;
  if (d[0] < 2 || d[1] < 2 || d[2] < 2) return 0;
  const auto nx = static_cast<size_t>(d[0]), plane = static_cast<size_t>(d[0] * d[1]);
  const float* values = volume.data();
  // Chunks of cell layers are independent; each sums an integer, so the total is the same on any
  // number of threads.
  constexpr int64_t kChunkLayers = 8;
  const int64_t chunks = (d[2] - 1 + kChunkLayers - 1) / kChunkLayers;
  std::vector<int64_t> per_chunk(static_cast<size_t>(chunks), 0);
  parallel_for(int64_t{0}, chunks, [&](int64_t chunk) {
    const int64_t z_begin = chunk * kChunkLayers, z_end = std::min(z_begin + kChunkLayers, d[2] - 1);
    // The signs of a plane of nodes, a byte each; the plane below a layer's cells and the one above.
    std::vector<uint8_t> below(plane), above(plane), column(nx);
    const auto signs = [&](int64_t z, std::vector<uint8_t>& plane_signs) {
      node_signs(values + static_cast<size_t>(z) * plane, plane, iso, plane_signs.data());
    };
    signs(z_begin, below);
    int64_t sum = 0;
    for (int64_t z = z_begin; z < z_end; ++z) {
      signs(z + 1, above);
      for (int64_t y = 0; y + 1 < d[1]; ++y) {
        const uint8_t* s00 = below.data() + static_cast<size_t>(y) * nx;  // node rows (y, z), (y + 1, z),
        const uint8_t* s10 = s00 + nx;                                    // (y, z + 1), (y + 1, z + 1)
        const uint8_t* s01 = above.data() + static_cast<size_t>(y) * nx;
        const uint8_t* s11 = s01 + nx;
        // A column of four nodes (x fixed) as bits 0, 2, 4, 6 of the sign case; a cell is its two.
        uint8_t* c = column.data();
        column_cases(s00, s10, s01, s11, nx, c);
        const size_t yz = static_cast<size_t>(((y & 1) << 1) | ((z & 1) << 2)) << 8;
        for (size_t x = 0; x + 1 < nx;) {
          // Eight cells of one sign (columns all below, or all above) make nothing: most of a volume.
          if (x + 9 <= nx) {
            uint64_t w;
            std::memcpy(&w, c + x, sizeof w);
            if ((w == 0 && c[x + 8] == 0) || (w == 0x5555555555555555ull && c[x + 8] == 0x55)) {
              x += 8;
              continue;
            }
          }
          for (const size_t stop = std::min(x + 8, nx - 1); x < stop; ++x)
            sum += table[yz | (x & 1) << 8 | static_cast<size_t>(c[x] | c[x + 1] << 1)];
        }
      }
      std::swap(below, above);
    }
    per_chunk[static_cast<size_t>(chunk)] = sum;
  });
  int64_t total = 0;
  for (const int64_t n : per_chunk) total += n;
  return total;
}

int64_t full_resolution_slab_layers(const std::array<int64_t, 3>& dims) {
  const int64_t layer_cells = std::max<int64_t>((dims[0] - 1) * (dims[1] - 1), 1);
  return std::max<int64_t>((kSlabCells + layer_cells - 1) / layer_cells, 1);
}

Mesh extract_full_resolution(const Volume& volume, float iso) {
  if (!std::isfinite(iso)) throw InvalidInput("the isovalue must be a finite number");
  const auto& d = volume.dims;
  SlabPlan plan;
  plan.cell_layers = std::max<int64_t>(d[2] - 1, 0);
  plan.slab_layers = full_resolution_slab_layers(d);
  // The welding keys, and so the quadrilateral splits, depend on the side: the same for all slabs.
  plan.side = std::max({d[0], d[1], d[2]});
  plan.layer_nodes = {d[0], d[1]};
  plan.iso = iso;
  plan.origin = volume.origin;
  plan.spacing = volume.spacing;
  return march_in_slabs(plan, [&](int64_t z_begin, int64_t z_end, MeshBuilder& builder) {
    march_layers(volume, iso, z_begin, z_end, builder);
  });
}

}  // namespace isotope
