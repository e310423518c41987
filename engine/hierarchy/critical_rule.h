#pragma once
// When refining a diamond changes the local topology of the isosurface, given the values at
// its polyhedron: the paper's rule (Sec. 4.4) and the exact rule of docs/METHOD.md.
// Ties: a node is inside iff value > t, so an isovalue equal to a data value behaves like one
// just above it. Intervals are half-open, [lo, hi); empty when lo >= hi.
#include <cstdint>
#if defined(__SSE2__)
#include <xmmintrin.h>
#endif

#include "engine/hierarchy/diamond.h"

namespace isotope {

struct IsoInterval {
  float lo = 1, hi = 0;
  bool empty() const { return !(lo < hi); }
  bool contains(float t) const { return lo <= t && t < hi; }
  float length() const { return empty() ? 0.0f : hi - lo; }
  void hull(const IsoInterval& o) {
    if (o.empty()) return;
    if (empty()) {
      *this = o;
      return;
    }
    lo = lo < o.lo ? lo : o.lo;
    hi = hi > o.hi ? hi : o.hi;
  }
};

// Values at the polyhedron vertices: fa, fb, fv and the ring in cycle order.
struct DiamondValues {
  PolyhedronType type = PolyhedronType::cube;
  float fa = 0, fb = 0, fv = 0;
  float ring[8] = {};
};

// Sign pattern (bit set = value > t) in the layout of the critical table (is_critical_pattern). Inline: both rules take
// it for nearly every vertex whose v lies beyond a and b.
inline uint32_t sign_pattern(const DiamondValues& d, float t) {
  uint32_t p = (d.fa > t ? 1u : 0u) | (d.fb > t ? 2u : 0u);
  const int r = ring_size(d.type);
#if defined(__SSE2__)
  // The ring's eight slots compared at once (a NaN compares false either way), those past the
  // ring masked out.
  const __m128 at = _mm_set1_ps(t);
  const auto ring = static_cast<uint32_t>(_mm_movemask_ps(_mm_cmpgt_ps(_mm_loadu_ps(d.ring), at))) |
                    static_cast<uint32_t>(_mm_movemask_ps(_mm_cmpgt_ps(_mm_loadu_ps(d.ring + 4), at))) << 4;
  return p | (ring & ((1u << r) - 1)) << 2;
#else
  for (int i = 0; i < r; ++i) p |= (d.ring[i] > t ? 1u : 0u) << (2 + i);
  return p;
#endif
}

// Paper: signs relative to f(v); if critical, I = [f(v), min(fa, fb)) or [max(fa, fb), f(v)).
IsoInterval paper_interval(const DiamondValues& d);

// Exact: refining changes the local topology at t iff a and b lie on one side of t, v on the
// other, and the pattern relative to t is critical. Evaluated on every elementary interval
// between the (at most 11) values; returns the hull of those where it fires.
IsoInterval exact_interval(const DiamondValues& d);

// The exact rule at one isovalue (for tests and explanations).
bool exact_rule_fires(const DiamondValues& d, float t);

}  // namespace isotope
