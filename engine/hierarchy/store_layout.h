#pragma once
// How the hierarchy is cut into bands and bricks for the out-of-core store (docs/FORMAT.md).
// Band j holds the nodes of the grid G_j (lattice multiples of 2^j): the values of all of them and
// the records of those of scale exactly j, i.e. the refinement vertices of levels 3(k-j)-3 ..
// 3(k-j)-1. A tetrahedron bisected at a scale-j vertex has its corners on G_j too, so a traversal
// that stops at scale j reads band j and nothing finer. Each band is cut into bricks of T^3 of
// its nodes, T = 2^brick_bits; the coarse bands are a single small brick each.
#include <array>
#include <cstdint>
#include <vector>

#include "engine/hierarchy/lattice.h"
#include "engine/hierarchy/record.h"
#include "isotope/store_defaults.h"

namespace isotope {

using Box3 = std::array<int64_t, 3>;  // per-axis counts or coordinates on a band's grid

struct Band {
  int scale = 0;
  std::array<int64_t, 3> nodes{};   // G_j nodes per axis: 0 .. record_extent >> j
  std::array<int64_t, 3> bricks{};  // bricks per axis
  int64_t first_brick = 0;          // directory index of its brick (0, 0, 0)
  int64_t brick_count() const { return bricks[0] * bricks[1] * bricks[2]; }
};

class StoreLayout {
 public:
  StoreLayout() = default;
  StoreLayout(const std::array<int64_t, 3>& dims, int brick_bits) : dims_(dims), brick_bits_(brick_bits) {
    lattice_ = Lattice::enclosing(dims);
    const int64_t t = brick_width();
    int64_t first = 0;
    for (int j = 0; j <= lattice_.k; ++j) {
      Band b;
      b.scale = j;
      for (int a = 0; a < 3; ++a) {
        b.nodes[a] = (record_extent(lattice_, dims, a, j) >> j) + 1;
        b.bricks[a] = (b.nodes[a] + t - 1) / t;
      }
      b.first_brick = first;
      first += b.brick_count();
      bands_.push_back(b);
    }
    brick_count_ = first;
  }

  // The brick size for a hierarchy held whole in memory: the store's (16^3), unless the volume is so
  // thin along an axis that such bricks would hold more than 4 slots per node of the bands (a
  // 500000x2x2 volume: 28, which took 4 GB for 2 MB of data); then the smaller brick (8^3 or
  // 4^3) that pads least. Meshes do not depend on the brick size.
  static int memory_brick_bits(const std::array<int64_t, 3>& dims) {
    auto slots = [&](int bits) { return StoreLayout(dims, bits).brick_count() << (3 * bits); };
    int64_t nodes = 0;
    const StoreLayout layout(dims, kDefaultBrickBits);
    for (const Band& b : layout.bands()) nodes += b.nodes[0] * b.nodes[1] * b.nodes[2];
    if (slots(kDefaultBrickBits) <= 4 * nodes) return kDefaultBrickBits;
    return slots(2) < slots(3) ? 2 : 3;
  }

  const Lattice& lattice() const { return lattice_; }
  const std::array<int64_t, 3>& dims() const { return dims_; }
  int brick_bits() const { return brick_bits_; }
  int64_t brick_width() const { return int64_t{1} << brick_bits_; }
  int64_t brick_nodes() const { return int64_t{1} << (3 * brick_bits_); }
  // Nodes of scale exactly j in a brick: those with a coordinate odd in G_j units (Morton code
  // not a multiple of 8).
  int64_t brick_records() const { return brick_nodes() - brick_nodes() / 8; }
  const std::vector<Band>& bands() const { return bands_; }
  const Band& band(int j) const { return bands_[static_cast<size_t>(j)]; }
  int64_t brick_count() const { return brick_count_; }
  // Directory index of brick b (brick coordinates) of band j.
  int64_t brick_index(int j, const std::array<int64_t, 3>& b) const {
    const Band& band = bands_[static_cast<size_t>(j)];
    return band.first_brick + (b[2] * band.bricks[1] + b[1]) * band.bricks[0] + b[0];
  }
  // Brick coordinates of directory index `index` of `band` (brick_index's inverse).
  static std::array<int64_t, 3> brick_of(const Band& band, int64_t index) {
    const int64_t i = index - band.first_brick;
    return {i % band.bricks[0], i / band.bricks[0] % band.bricks[1], i / (band.bricks[0] * band.bricks[1])};
  }

 private:
  Lattice lattice_;
  std::array<int64_t, 3> dims_{};
  int brick_bits_ = kDefaultBrickBits;
  std::vector<Band> bands_;
  int64_t brick_count_ = 0;
};

// Morton code of (x, y, z), each below 2^21: x in bit 0, y in bit 1, z in bit 2, then upwards.
inline uint64_t morton_encode(uint64_t x, uint64_t y, uint64_t z) {
  uint64_t m = 0;
  for (int i = 0; i < 21; ++i)
    m |= ((x >> i & 1) << (3 * i)) | ((y >> i & 1) << (3 * i + 1)) | ((z >> i & 1) << (3 * i + 2));
  return m;
}
inline std::array<int64_t, 3> morton_decode(uint64_t m) {
  std::array<int64_t, 3> c{0, 0, 0};
  for (int i = 0; i < 21; ++i)
    for (int a = 0; a < 3; ++a) c[static_cast<size_t>(a)] |= static_cast<int64_t>((m >> (3 * i + a)) & 1) << i;
  return c;
}

// Position of local node (x, y, z) of a brick in the values array, and of a scale-j node in the
// records array.
// Spreads the low 10 bits of v to every third bit (brick coordinates have at most 8).
constexpr uint32_t spread_bits_3(int64_t v) {
  auto x = static_cast<uint32_t>(v) & 0x3ffu;
  x = (x | x << 16) & 0x30000ffu;
  x = (x | x << 8) & 0x300f00fu;
  x = (x | x << 4) & 0x30c30c3u;
  x = (x | x << 2) & 0x9249249u;
  return x;
}
// spread_bits_3 of every brick coordinate, by table: the loops that place a brick's nodes (the
// store's writer and reader, the hierarchy in memory) look their bits up here.
inline constexpr std::array<uint32_t, 256> kSpreadBits3 = [] {
  std::array<uint32_t, 256> t{};
  for (size_t i = 0; i < t.size(); ++i) t[i] = spread_bits_3(static_cast<int64_t>(i));
  return t;
}();
// The inverse: every third bit of m, from bit 0, packed.
inline int64_t compact_bits_3(uint32_t m) {
  uint32_t x = m & 0x9249249u;
  x = (x | x >> 2) & 0x30c30c3u;
  x = (x | x >> 4) & 0x300f00fu;
  x = (x | x >> 8) & 0x30000ffu;
  x = (x | x >> 16) & 0x3ffu;
  return x;
}
inline uint32_t brick_morton(int64_t x, int64_t y, int64_t z, [[maybe_unused]] int bits) {
  return spread_bits_3(x) | spread_bits_3(y) << 1 | spread_bits_3(z) << 2;
}
inline uint32_t brick_record_index(uint32_t morton) { return (morton >> 3) * 7 + (morton & 7) - 1; }

}  // namespace isotope
