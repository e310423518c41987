#pragma once
// What every consumer of a volume refuses (one check for the command, the C++ API, the Python
// module and the server's store): dimensions outside 2 .. 2^19 + 1 per axis (the traversal packs
// coordinates in 21 bits), a spacing that is not finite and positive, an origin that is not finite,
// a geometry whose far corner lies beyond the mesh's float32 coordinates, values that do not fill
// the dimensions, values that are not finite.
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>

#include "isotope/volume.h"

namespace isotope {

// Whether V converts to a finite float (false for NaN): values, coordinates and value ranges are
// float32 however a file gives them.
inline bool within_float_range(double v) { return std::fabs(v) <= std::numeric_limits<float>::max(); }

// Dimensions alone (a hierarchy's lattice, before there is a volume). Throws InvalidInput.
void validate_dims(const std::array<int64_t, 3>& dims);

// Dimensions and geometry, before any value is read. Throws InvalidInput naming the
// first problem and the numbers, e.g. "volume dimensions 8x16x1 (x by y by z): every axis needs
// 2 .. 524289 nodes".
void validate_layout(const std::array<int64_t, 3>& dims, const std::array<double, 3>& spacing,
                     const std::array<double, 3>& origin);

// validate_layout, then the values. Throws InvalidInput naming the first problem (a value
// by its x, y, z).
void validate_volume(const Volume& volume);

// The index of the first of COUNT values that is not finite (NaN or infinite), or COUNT. On all
// threads, a block of values at a time, each block tested without a branch per value: a volume of
// 2^24 floats is checked at the memory's pace, not at a comparison and a branch per value.
size_t first_non_finite(const float* values, size_t count);

}  // namespace isotope
