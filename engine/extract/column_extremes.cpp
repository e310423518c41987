#include "engine/extract/column_extremes.h"

#include <type_traits>

namespace isotope {
namespace {

template <class T, bool kFindNan>
[[gnu::always_inline]] inline bool fold(const T* row, size_t width, T* low, T* high) {
  int nan = 0;
  for (size_t x = 0; x < width; ++x) {
    low[x] = row[x] < low[x] ? row[x] : low[x];
    high[x] = row[x] > high[x] ? row[x] : high[x];
    if constexpr (kFindNan) nan |= row[x] != row[x];
  }
  return nan != 0;
}

#if defined(__x86_64__) && defined(__GNUC__)
template <class T, bool kFindNan>
[[gnu::target("avx2")]] bool fold_avx2(const T* row, size_t width, T* low, T* high) {
  return fold<T, kFindNan>(row, width, low, high);
}
bool has_avx2() {
  static const bool avx2 = __builtin_cpu_supports("avx2");
  return avx2;
}
#endif

template <class T, bool kFindNan>
bool fold_any(const T* row, size_t width, T* low, T* high) {
#if defined(__x86_64__) && defined(__GNUC__)
  if (has_avx2()) return fold_avx2<T, kFindNan>(row, width, low, high);
#endif
  return fold<T, kFindNan>(row, width, low, high);
}

}  // namespace

// An integer is never NaN: only floats look for one, and only when asked.
template <class T>
bool fold_row_extremes(const T* row, size_t width, T* low, T* high, bool find_nan) {
  if constexpr (!std::is_integral_v<T>)
    if (find_nan) return fold_any<T, true>(row, width, low, high);
  return fold_any<T, false>(row, width, low, high);
}

template <class T>
bool fold_row_extremes_baseline(const T* row, size_t width, T* low, T* high, bool find_nan) {
  if constexpr (!std::is_integral_v<T>)
    if (find_nan) return fold<T, true>(row, width, low, high);
  return fold<T, false>(row, width, low, high);
}

#define ISOTOPE_FOLD_ROW_EXTREMES(T)                                  \
  template bool fold_row_extremes<T>(const T*, size_t, T*, T*, bool); \
  template bool fold_row_extremes_baseline<T>(const T*, size_t, T*, T*, bool);
ISOTOPE_FOLD_ROW_EXTREMES(float)
ISOTOPE_FOLD_ROW_EXTREMES(uint8_t)
ISOTOPE_FOLD_ROW_EXTREMES(uint16_t)
ISOTOPE_FOLD_ROW_EXTREMES(int16_t)
#undef ISOTOPE_FOLD_ROW_EXTREMES

}  // namespace isotope
