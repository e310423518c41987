#include "engine/hierarchy/critical_rule.h"

#include <algorithm>
#include <array>

#include "engine/hierarchy/critical_table.h"

namespace isotope {

uint32_t sign_pattern(const DiamondValues& d, float t) {
  uint32_t p = (d.fa > t ? 1u : 0u) | (d.fb > t ? 2u : 0u);
  const int r = ring_size(d.type);
  for (int i = 0; i < r; ++i) p |= (d.ring[i] > t ? 1u : 0u) << (2 + i);
  return p;
}

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
  if (d.fv >= std::min(d.fa, d.fb) && d.fv <= std::max(d.fa, d.fb)) return {};
  std::array<float, 11> w{};
  const int r = ring_size(d.type);
  w[0] = d.fa;
  w[1] = d.fb;
  w[2] = d.fv;
  std::copy(d.ring, d.ring + r, w.begin() + 3);
  std::sort(w.begin(), w.begin() + 3 + r);
  const int n = static_cast<int>(std::unique(w.begin(), w.begin() + 3 + r) - w.begin());
  // On [w[i], w[i+1]) every sign is that of t = w[i] (value > w[i]); outside [w[0], w[n-1])
  // all signs agree and nothing fires.
  IsoInterval x;
  for (int i = 0; i + 1 < n; ++i)
    if (exact_rule_fires(d, w[i])) x.hull({w[i], w[i + 1]});
  return x;
}

}  // namespace isotope
