#pragma once
// Writes generated volumes: raw (little-endian, x fastest) in any ScalarType, or an HDF5 dataset
// "/volume" of shape (z, y, x) in float32.
#include <string>

#include "io/volume/raw_reader.h"
#include "isotope/volume.h"

namespace isotope {

// How write_raw stores a value v. Float types store v itself. Integer types cannot hold the
// field's values, so its [min, max] is stretched onto the type's whole range, losing as little
// resolution as the type allows: stored = round(first + (v - min) * scale). A constant field
// stores `first`.
struct RawEncoding {
  ScalarType type = ScalarType::float32;
  double min = 0, max = 0;      // the field's range
  double first = 0, scale = 1;  // the lowest code, and codes per unit of v
  bool is_mapped() const;       // integer type: the stored values are codes, not v
  // The unrounded code of V: the isovalue to ask of the written file for the surface at V.
  double code(double v) const;
};

RawEncoding raw_encoding(const Volume& volume, ScalarType type);  // throws IoError on NaN/inf for integer types
// Atomic; throws IoError. Streams the converted values out in blocks, so the only copy in
// memory is VOLUME itself. Returns the encoding it used.
RawEncoding write_raw(const Volume& volume, const std::string& path, ScalarType type);
void write_hdf5(const Volume& volume, const std::string& path);  // float32; atomic; throws IoError

}  // namespace isotope
