#pragma once
// Four float lanes reduced to one: the least or the greatest of them. MINPS and MAXPS between
// equal values keep one operand, so that of -0 and 0 the lane order decides which is kept;
// callers use these where no -0 is among the values, or where either is as good.
#if defined(__SSE2__)
#include <xmmintrin.h>

namespace isotope {

inline float least_lane(__m128 v) {
  v = _mm_min_ps(v, _mm_shuffle_ps(v, v, _MM_SHUFFLE(1, 0, 3, 2)));
  return _mm_cvtss_f32(_mm_min_ss(v, _mm_shuffle_ps(v, v, _MM_SHUFFLE(2, 3, 0, 1))));
}

inline float greatest_lane(__m128 v) {
  v = _mm_max_ps(v, _mm_shuffle_ps(v, v, _MM_SHUFFLE(1, 0, 3, 2)));
  return _mm_cvtss_f32(_mm_max_ss(v, _mm_shuffle_ps(v, v, _MM_SHUFFLE(2, 3, 0, 1))));
}

}  // namespace isotope
#endif
