#pragma once
// A plain array as a source of values only: what eps = 0 reads (the finest extraction).
// The array may hold only some z-layers of the volume (a window of a volume streamed from a file).
#include <algorithm>
#include <array>
#include <cstdint>
#include <limits>
#include <stdexcept>
#include <type_traits>
#include <vector>

#include "engine/extract/column_extremes.h"
#include "engine/hierarchy/lattice.h"
#include "isotope/error.h"
#include "isotope/volume.h"

namespace isotope {

// What ArrayReader::block_cut throws, asked to check, on a block holding a value that is not
// finite: the caller names the value (where it is, in which file) by reading it again.
struct NonFiniteValue : InvalidInput {
  NonFiniteValue() : InvalidInput("a value of the volume is not finite (NaN or infinite)") {}
};

// Reads node values by their global coordinates from an array of whole z-layers, of T (float, or
// an integer type the values were stored as, read as float): layer z of the volume is layer
// z - z_first of the array. value() clamps coordinates beyond the volume to its
// last node (the lattice may reach beyond the data), which an array of some layers holds only if
// it is the last; extract_finest reads blocks, which lie inside the data box, through
// block_values, and never calls value() on an array that holds only some layers.
template <class T = float>
class ArrayReader {
 public:
  // CHECKS: the values were not checked for being finite when read; block_cut then checks them.
  ArrayReader(const T* values, const std::array<int64_t, 3>& dims, int64_t z_first, bool checks = false)
      : values_(values),
        dims_(dims),
        z_first_(z_first),
        checks_(checks && !std::is_integral_v<T>) {}  // an integer is finite
  float value(const Coord& c, int /*band*/) const {
    return static_cast<float>(
        values_[index(std::min(c[0], dims_[0] - 1), std::min(c[1], dims_[1] - 1), std::min(c[2], dims_[2] - 1))]);
  }
  // Whether min <= iso < max over the block's nodes (cut_by), read where they are: most blocks
  // are not cut, and are then never copied. Blocks are asked for a row at a time (the same y and
  // z extent, x increasing): the first block of a row takes the least and greatest value of each
  // x column over the row's nodes, a whole array row at a time, which vectorizes, and each block
  // then looks at its own columns only. Scanning each block's rows of nine values was 8% of the
  // one-shot eps 0 process. Values are finite, checked when read, or here when the reader was
  // made to check: the same pass looks for a NaN, and the columns' extremes for an infinity, so
  // that a streamed volume is not read twice, once to check and once to march. The rows of the
  // blocks of a slab are every node of its layers, when each axis has two nodes at least. The pass
  // over a row runs with AVX2 where the processor has it (fold_row_extremes).
  bool block_cut(const Coord& lo, const std::array<int64_t, 3>& n, float iso) {
    if (lo[1] != row_[0] || lo[2] != row_[1] || n[1] != row_[2] || n[2] != row_[3]) {
      row_ = {lo[1], lo[2], n[1], n[2]};
      const auto width = static_cast<size_t>(dims_[0]);
      low_.assign(width, kHighest);
      high_.assign(width, kLowest);
      T* low = low_.data();
      T* high = high_.data();
      bool nan = false;
      for (int64_t z = 0; z <= n[2]; ++z)
        for (int64_t y = 0; y <= n[1]; ++y)
          nan |= fold_row_extremes(values_ + index(0, lo[1] + y, lo[2] + z), width, low, high, checks_);
      if (checks_) {
        // An infinity is a column's least or greatest value; a NaN is neither (no comparison holds).
        for (size_t x = 0; x < width; ++x) nan |= low[x] == kLowest || high[x] == kHighest;
        if (nan) throw NonFiniteValue();
      }
    }
    bool below = false, above = false;
    // Converting to float keeps the order: the least and greatest values are the floats'.
    for (int64_t x = lo[0]; x <= lo[0] + n[0]; ++x) {
      below |= static_cast<float>(low_[static_cast<size_t>(x)]) <= iso;
      above |= static_cast<float>(high_[static_cast<size_t>(x)]) > iso;
    }
    return below && above;
  }
  // Blocks lie in the data box (extract_finest cuts them there): whole rows of the array.
  bool block_values(const Coord& lo, const std::array<int64_t, 3>& n, float* f, int64_t stride) const {
    for (int64_t z = 0; z <= n[2]; ++z)
      for (int64_t y = 0; y <= n[1]; ++y) {
        const T* row = values_ + index(lo[0], lo[1] + y, lo[2] + z);
        std::copy(row, row + n[0] + 1, f + (z * stride + y) * stride);  // as float
      }
    return true;
  }

 private:
  // A float column starts at the infinities (which only a value that is not finite reaches), an
  // integer one at its type's extremes.
  static constexpr T kHighest =
      std::numeric_limits<T>::has_infinity ? std::numeric_limits<T>::infinity() : std::numeric_limits<T>::max();
  static constexpr T kLowest =
      std::numeric_limits<T>::has_infinity ? -std::numeric_limits<T>::infinity() : std::numeric_limits<T>::lowest();
  size_t index(int64_t x, int64_t y, int64_t z) const {
    return static_cast<size_t>(((z - z_first_) * dims_[1] + y) * dims_[0] + x);
  }
  const T* values_;
  std::array<int64_t, 3> dims_;
  int64_t z_first_;
  bool checks_;
  // block_cut's row of blocks (its y, z, and node extents) and its columns' least and greatest values.
  std::array<int64_t, 4> row_{-1, -1, -1, -1};
  std::vector<T> low_, high_;
};

// A whole volume in memory.
class ArraySource {
 public:
  explicit ArraySource(const Volume& v) : v_(v), lattice_(Lattice::enclosing(v.dims)) {}
  const Lattice& lattice() const { return lattice_; }
  const std::array<int64_t, 3>& data_dims() const { return v_.dims; }
  const std::array<double, 3>& origin() const { return v_.origin; }
  const std::array<double, 3>& spacing() const { return v_.spacing; }
  // v_.data() once per reader: Volume::at chooses between owned and borrowed values per call.
  ArrayReader<> reader() const { return ArrayReader<>(v_.data(), v_.dims, 0); }

 private:
  const Volume& v_;
  Lattice lattice_;
};

}  // namespace isotope
