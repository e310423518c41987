#pragma once
// The saturated record (Record) in a few bytes (docs/FORMAT.md, "Compact records"). The
// guaranteed error bound is kept as the float it is; every other field becomes a bfloat16 code,
// the upper half of its float's bits, rounded in the direction that can only make the traversal
// refine more:
//   - ranges outward (lo down, hi up): a looser range culls less, which costs visits but never
//     changes the mesh (a culled tetrahedron has no sign change, and neither has a tetrahedron
//     whose corner values all miss the isovalue);
//   - the paper's surplus and the weights up: refines where the exact record might have stopped,
//     never the other way round;
//   - critical intervals outward: the rule fires on a superset of isovalues.
// Each rounding is one fixed monotone map, and these fields saturate by min, max and hull, which
// commute with it: the rounded saturation of the exact records equals the saturation of the rounded
// ones. So a parent's code is never below a child's (the conforming, crack-free cut of
// the traversal survives), a record may be computed from its children's compact records (a
// store's band 0, PagedVolume) with the same bits as from exact ones, and the bound, a sum
// over the levels, is not rounded at all: eps keeps its L-infinity meaning exactly. A bfloat16 keeps
// 8 significant bits: a range, surplus or weight moves by at most 2^-8 of itself.
#include <bit>
#include <cstdint>
#include <limits>

#include "engine/hierarchy/record.h"

namespace isotope {

using Bf16 = uint16_t;

inline float bf16_to_float(Bf16 c) { return std::bit_cast<float>(static_cast<uint32_t>(c) << 16); }

// The smallest bfloat16 >= f (f not NaN; +inf stays +inf).
inline Bf16 bf16_up(float f) {
  const uint32_t bits = std::bit_cast<uint32_t>(f);
  const auto high = static_cast<Bf16>(bits >> 16);
  if ((bits & 0xffffu) == 0) return high;
  // Positive: the next larger magnitude (a carry into the exponent is still the next float up).
  // Negative: truncation moves towards zero, i.e. up. -0 and +0 have no low bits.
  return (bits >> 31) == 0 ? static_cast<Bf16>(high + 1) : high;
}

// The largest bfloat16 <= f (f not NaN).
inline Bf16 bf16_down(float f) {
  const uint32_t bits = std::bit_cast<uint32_t>(f);
  const auto high = static_cast<Bf16>(bits >> 16);
  if ((bits & 0xffffu) == 0) return high;
  return (bits >> 31) == 0 ? high : static_cast<Bf16>(high + 1);
}

// What every visit reads: the range and the guaranteed bound, in one 64-bit word (a store's band-0
// records are computed on first use by whichever thread gets there: PagedVolume).
struct PackedBounds {
  Bf16 lo = 0, hi = 0;
  float bound = 0;
};
inline uint64_t bounds_word(const PackedBounds& p) {
  return uint64_t{p.lo} | uint64_t{p.hi} << 16 | uint64_t{std::bit_cast<uint32_t>(p.bound)} << 32;
}
inline PackedBounds bounds_of(uint64_t w) {
  return {static_cast<Bf16>(w), static_cast<Bf16>(w >> 16), std::bit_cast<float>(static_cast<uint32_t>(w >> 32))};
}
// A word's range and bound as a traversal reads them (error_surplus 0: another field).
inline DiamondBounds range_bound(uint64_t w) {
  const PackedBounds p = bounds_of(w);
  return {bf16_to_float(p.lo), bf16_to_float(p.hi), p.bound, 0.0f};
}

// What a tetrahedron that the error would let stop reads in topology modes, and the paper's
// surplus (only --error surplus reads it).
struct PackedTopology {
  Bf16 exact_lo = 0, exact_hi = 0, paper_lo = 0, paper_hi = 0;
  Bf16 weight[3] = {0, 0, 0};
  Bf16 surplus = 0;
};

inline PackedBounds pack_bounds(const DiamondBounds& b) { return {bf16_down(b.lo), bf16_up(b.hi), b.error_bound}; }

// An empty interval (lo >= hi) stays empty. A record's "none", (+infinity, -infinity), is written
// {1, 0}, exact in bf16: the words stores have always held for it (docs/FORMAT.md).
inline void pack_interval(float lo, float hi, Bf16& packed_lo, Bf16& packed_hi) {
  const bool none = lo == DiamondTopology::kNone;
  packed_lo = none ? bf16_down(1.0f) : bf16_down(lo);
  packed_hi = none ? bf16_up(0.0f) : bf16_up(hi);
}
inline PackedTopology pack_topology(const DiamondTopology& t, float surplus) {
  PackedTopology p;
  p.surplus = bf16_up(surplus);
  pack_interval(t.exact_lo, t.exact_hi, p.exact_lo, p.exact_hi);
  pack_interval(t.paper_lo, t.paper_hi, p.paper_lo, p.paper_hi);
  for (int w = 0; w < 3; ++w) p.weight[w] = bf16_up(t.weight[static_cast<size_t>(w)]);
  return p;
}
inline DiamondTopology unpack(const PackedTopology& p) {
  DiamondTopology t;
  t.exact_lo = bf16_to_float(p.exact_lo);
  t.exact_hi = bf16_to_float(p.exact_hi);
  t.paper_lo = bf16_to_float(p.paper_lo);
  t.paper_hi = bf16_to_float(p.paper_hi);
  for (int w = 0; w < 3; ++w) t.weight[static_cast<size_t>(w)] = bf16_to_float(p.weight[w]);
  return t;
}

// The record conservatively rounded, as the compact hierarchy and the store hold it.
inline Record round_record(const Record& r) {
  const PackedBounds b = pack_bounds(r.bounds);
  const PackedTopology t = pack_topology(r.topology, r.bounds.error_surplus);
  return {{bf16_to_float(b.lo), bf16_to_float(b.hi), b.bound, bf16_to_float(t.surplus)}, unpack(t)};
}

}  // namespace isotope
