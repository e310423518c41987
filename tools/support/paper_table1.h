#pragma once
// The paper's Table 1 (Gerstner & Pajarola 2000, Sec. 4.5): the algebraic function on a 65^3 grid
// at iso 0, triangles without and with topology preservation for five eps. `isotope demo` and
// `isotope bench` print our counts beside these.
namespace isotope::tools {

struct Table1Eps {
  const char* label;  // as the paper prints it
  double value;
};
struct Table1Row {
  int without, with;
};

inline constexpr Table1Eps kTable1Eps[5] = {
    {"0", 0.0}, {"1/64", 1.0 / 64}, {"1/16", 1.0 / 16}, {"1/4", 0.25}, {"1", 1.0}};
inline constexpr Table1Row kTable1Paper[5] = {{59290, 59290}, {25456, 25464}, {7124, 7528}, {1936, 3503}, {374, 3095}};

}  // namespace isotope::tools
