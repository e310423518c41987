#pragma once
// The pass that culls the blocks of eps 0 by their columns' extremes (ArrayReader::block_cut):
// every value of a streamed volume goes through it once, so it is compiled twice, for the
// baseline x86-64 and for AVX2 (twice the values an instruction), and the build the processor
// can run is picked at run time.
#include <cstddef>
#include <cstdint>

namespace isotope {

// Folds ROW's WIDTH values into LOW and HIGH, each column's least and greatest so far. With
// FIND_NAN (floats), also whether a value was NaN, which no comparison folds. For float, uint8_t,
// uint16_t and int16_t.
template <class T>
bool fold_row_extremes(const T* row, size_t width, T* low, T* high, bool find_nan);

// The same, compiled for the baseline only, whatever the processor: what one without AVX2 runs,
// for the tests that compare the two.
template <class T>
bool fold_row_extremes_baseline(const T* row, size_t width, T* low, T* high, bool find_nan);

}  // namespace isotope
