#include "engine/hierarchy/critical_rule.h"

#include <algorithm>
#include <array>

#include "engine/hierarchy/critical_table.h"

namespace isotope {

IsoInterval paper_interval(const DiamondValues& d) {
  // Every critical pattern has equal signs at a and b (tests/critical_table_test.cpp): most
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
  // of all the values that lie in [from, to), the rest cannot fire.
  std::array<float, 9> w{};
  int n = 0;
  w[static_cast<size_t>(n++)] = from;
  const int r = ring_size(d.type);
  for (int i = 0; i < r; ++i)
    if (d.ring[i] > from && d.ring[i] < to) {
      // Insertion into the sorted starts, equal values once.
      int k = n;
      while (k > 0 && w[static_cast<size_t>(k - 1)] > d.ring[i]) --k;
      if (w[static_cast<size_t>(k - 1)] == d.ring[i]) continue;  // k >= 1: w[0] = from < ring[i]
      for (int m = n; m > k; --m) w[static_cast<size_t>(m)] = w[static_cast<size_t>(m - 1)];
      w[static_cast<size_t>(k)] = d.ring[i];
      ++n;
    }
  IsoInterval x;
  for (int i = 0; i < n; ++i) {
    // a and b on one side of t, v on the other, throughout [from, to): the table decides.
    const float t = w[static_cast<size_t>(i)];
    if (is_critical_pattern(d.type, sign_pattern(d, t))) x.hull({t, i + 1 < n ? w[static_cast<size_t>(i + 1)] : to});
  }
  return x;
}

}  // namespace isotope
