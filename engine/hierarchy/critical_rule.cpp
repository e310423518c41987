#include "engine/hierarchy/critical_rule.h"

#include <algorithm>
#include <bit>

#include "engine/hierarchy/critical_table.h"

namespace isotope {

IsoInterval paper_interval(const DiamondValues& d) {
  // Every critical pattern has equal signs at a and b (a test of the critical table holds it): most
  // vertices of smooth data lie between their edge's ends and are settled without the table.
  if ((d.fa > d.fv) != (d.fb > d.fv)) return {};
  // Relative to f(v) itself: a tie counts as '-', as it does for t = f(v) in marching tetrahedra.
  if (!is_critical_pattern(d.type, sign_pattern(d, d.fv))) return {};
  const bool a_plus = d.fa > d.fv, b_plus = d.fb > d.fv;
  if (a_plus && b_plus) return {d.fv, std::min(d.fa, d.fb)};
  if (!a_plus && !b_plus) return {std::max(d.fa, d.fb), d.fv};
  return {};  // unreachable: critical patterns have equal signs at a and b (tested)
}

bool exact_rule_fires(const DiamondValues& d, float t) {
  const bool sa = d.fa > t, sb = d.fb > t, sv = d.fv > t;
  return sa == sb && sv != sa && is_critical_pattern(d.type, sign_pattern(d, t));
}

IsoInterval exact_interval(const DiamondValues& d) {
  // It can only fire where v lies strictly beyond both a and b: t in [fv, min(fa, fb)) or
  // [max(fa, fb), fv). Most vertices of smooth data lie between their edge's ends.
  const float ab_lo = std::min(d.fa, d.fb), ab_hi = std::max(d.fa, d.fb);
  if (d.fv >= ab_lo && d.fv <= ab_hi) return {};
  const bool v_below = d.fv < ab_lo;
  const float from = v_below ? d.fv : ab_hi, to = v_below ? ab_lo : d.fv;
  // On each elementary interval between the polyhedron's values the signs are those at its first
  // value (value > t). In [from, to) those intervals start at `from` (a value) and at the ring
  // values strictly inside; each ends at the next start or at `to` (a value too): the intervals
  // of all the values that lie in [from, to), the rest cannot fire. Throughout, a and b lie on
  // one side of t (above it when v is below) and v on the other: the table decides. The hull of
  // the intervals where it fires runs from the least such start to the end of the greatest,
  // the next start above it; of equal ring values the first in ring order stands for them all.
  const int r = ring_size(d.type);
  uint32_t inside = 0;
  for (int i = 0; i < r; ++i) inside |= (d.ring[i] > from && d.ring[i] < to ? 1u : 0u) << i;
  bool fired = is_critical_pattern(d.type, sign_pattern(d, from));
  float lo = from, last = from;  // the least and the greatest start where the rule fires
  for (uint32_t rest = inside; rest != 0; rest &= rest - 1) {
    const float t = d.ring[std::countr_zero(rest)];
    if (!is_critical_pattern(d.type, sign_pattern(d, t))) continue;
    if (!fired || t < lo) lo = t;
    if (!fired || t > last) last = t;
    fired = true;
  }
  if (!fired || !(lo < to)) return {};
  float hi = to;
  for (uint32_t rest = inside; rest != 0; rest &= rest - 1) {
    const float t = d.ring[std::countr_zero(rest)];
    if (t > last && t < hi) hi = t;
  }
  return {lo, hi};
}

}  // namespace isotope
