#pragma once
// Headerless little-endian volumes, x fastest (Open SciVis layout).
#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "isotope/volume.h"  // Volume, ScalarType

namespace isotope {

struct RawLayout {
  std::array<int64_t, 3> dims{0, 0, 0};
  ScalarType type = ScalarType::uint8;
};

// "lobster_301x324x56_uint8.raw" -> {301,324,56}, uint8; nullopt when the name does not say.
std::optional<RawLayout> parse_raw_name(const std::string& path);

class BoxReader;
// A raw file read by boxes (BoxReader): checked against LAYOUT at open.
std::unique_ptr<BoxReader> open_raw_box_reader(const std::string& path, const RawLayout& layout);

// Throws IoError: missing/unreadable file, size not equal to the layout, NaN or infinite values.
Volume read_raw(const std::string& path, const RawLayout& layout);
// What read_raw checks before reading: the file exists, is not a directory, and holds exactly the
// layout's bytes. Throws IoError naming PATH; returns the byte count.
int64_t check_raw_file(const std::string& path, const RawLayout& layout);

// Shared by the readers and writers. Throws IoError naming FILE when a dimension is < 1 or
// dims[0]*dims[1]*dims[2]*element_bytes does not fit in int64; returns the node count.
int64_t checked_node_count(const std::array<int64_t, 3>& dims, int element_bytes, const std::string& file);

// The volume's dimensions and geometry as every consumer takes them (validate_layout),
// checked for FILE: by open_box_reader before any value is read, by read_volume once it has read
// them; throws IoError naming FILE and the numbers.
void check_volume_layout(const std::array<int64_t, 3>& dims, const std::array<double, 3>& spacing,
                         const std::array<double, 3>& origin, const std::string& file);
// Throws IoError naming FILE and the (x, y, z) of the first NaN or infinite value.
void check_finite(const Volume& volume, const std::string& file);
// The same for a box of SIZE nodes at LO (x fastest); the message gives global coordinates.
void check_finite(const float* values, const std::array<int64_t, 3>& lo, const std::array<int64_t, 3>& size,
                  const std::string& file);
// COUNT values stored as TYPE in the given byte order at IN, converted to float. A float64 beyond
// float range becomes infinite, so check_finite reports it instead of the conversion being undefined.
void decode_scalars(ScalarType type, bool big_endian, const unsigned char* in, size_t count, float* out);

}  // namespace isotope
