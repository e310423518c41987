#pragma once
// The saturated per-vertex record (docs/METHOD.md, "Per-vertex records") and where records exist.
#include <algorithm>
#include <array>
#include <bit>
#include <cstdint>
#include <limits>

#include "engine/hierarchy/lattice.h"

namespace isotope {

// What every visit of the traversal reads: saturated range and errors of v's diamond.
struct DiamondBounds {
  float lo = 0, hi = 0;     // value range of every node below v
  float error_bound = 0;    // guaranteed L-infinity bound
  float error_surplus = 0;  // the paper's saturated surplus eta_bar
};

// What only a tetrahedron that the error would let stop reads. Intervals are half-open
// [lo, hi), empty when lo >= hi. A record without one holds (+infinity, -infinity): what the hull
// of no interval is, so that a vertex folds its children's intervals by min and max alone, with
// no test for emptiness (ChildFold). The store writes it as {1, 0} (pack_topology).
struct DiamondTopology {
  static constexpr float kNone = std::numeric_limits<float>::infinity();
  float exact_lo = kNone, exact_hi = -kNone;  // hull X_bar of isovalues where the exact rule fires
  float paper_lo = kNone, paper_hi = -kNone;  // hull I_bar of the paper's critical intervals
  // Saturated simplification weights (max over the subtree), indexed by SimplificationWeight
  // (an extraction option): |X|, |X| times the steepest gradient around v, and the local isosurface
  // size (local_weights).
  std::array<float, 3> weight{0, 0, 0};
};

struct Record {
  DiamondBounds bounds;
  DiamondTopology topology;
};

// Scale of a node: the number of trailing zero bits its coordinates share (at most k). Nodes of
// scale j are the refinement vertices of levels 3(k-j)-3 .. 3(k-j)-1; the 8 corners (scale k)
// are none.
inline int scale_of(const Coord& v, const Lattice& lattice) {
  const auto bits = static_cast<uint64_t>(v[0] | v[1] | v[2]);
  return bits == 0 ? lattice.k : std::min(lattice.k, std::countr_zero(bits));
}

// Largest coordinate along axis a with a record at scale j: records stop 2^j beyond the data
// box, since a tetrahedron whose refinement vertex lies farther out is beyond a face of the
// box and the traversal never reads it (its corners are within 2^j of that vertex).
inline int64_t record_extent(const Lattice& lattice, const std::array<int64_t, 3>& dims, int a, int j) {
  return std::min(lattice.n, (dims[a] - 1 + (int64_t{1} << j)) >> j << j);
}

}  // namespace isotope
