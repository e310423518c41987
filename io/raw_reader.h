#pragma once
// Headerless little-endian volumes, x fastest (Open SciVis layout).
#include <array>
#include <cstdint>
#include <optional>
#include <string>

#include "engine/volume.h"

namespace isotope {

enum class ScalarType { uint8, uint16, int16, float32, float64 };

struct RawLayout {
  std::array<int64_t, 3> dims{0, 0, 0};
  ScalarType type = ScalarType::uint8;
};

// "lobster_301x324x56_uint8.raw" -> {301,324,56}, uint8; nullopt when the name does not say.
std::optional<RawLayout> parse_raw_name(const std::string& path);
std::optional<ScalarType> parse_scalar_type(const std::string& name);  // uint8|uint16|int16|float32|float64
const char* scalar_type_name(ScalarType t);
int scalar_type_size(ScalarType t);

// Throws IoError: missing/unreadable file, size not equal to the layout, NaN or infinite values.
Volume read_raw(const std::string& path, const RawLayout& layout);

}  // namespace isotope
