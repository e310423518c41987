#pragma once
// A scalar volume held in memory, and the element types isotope reads from files.
#include <array>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <vector>

namespace isotope {

// Nodes on a regular grid, x fastest, then y, then z (a numpy array a[z, y, x] in C order).
struct Volume {
  std::array<int64_t, 3> dims{0, 0, 0};    // nodes per axis (x, y, z)
  std::array<double, 3> spacing{1, 1, 1};  // physical distance between nodes
  std::array<double, 3> origin{0, 0, 0};   // physical position of node (0,0,0)
  std::vector<float> values;               // dims[0]*dims[1]*dims[2], x fastest
  // Instead of `values`: values that live elsewhere (a numpy array, a simulation's field), read
  // where they are, never copied. The caller keeps them alive and unchanged while this Volume, or
  // a Source opened from it, is in use (the Python module holds the array: isotope._isotope):
  // its values are checked once, when it is opened, and read as they are at each later moment.
  std::span<const float> borrowed;

  int64_t node_count() const { return dims[0] * dims[1] * dims[2]; }
  size_t index(int64_t x, int64_t y, int64_t z) const { return static_cast<size_t>((z * dims[1] + y) * dims[0] + x); }
  // The values, wherever they are: `borrowed` when set, else `values`.
  const float* data() const { return borrowed.data() ? borrowed.data() : values.data(); }
  size_t size() const { return borrowed.data() ? borrowed.size() : values.size(); }
  float at(int64_t x, int64_t y, int64_t z) const { return data()[index(x, y, z)]; }
};

// The element types of raw files (and what NRRD and HDF5 inputs are read as).
enum class ScalarType { uint8, uint16, int16, float32, float64 };

std::optional<ScalarType> parse_scalar_type(const std::string& name);  // uint8|uint16|int16|float32|float64
const char* scalar_type_name(ScalarType t);
// "301x324x56" -> {301, 324, 56} (x, y, z), as --dims takes it; digits only and each >= 1, so signs
// and blanks are rejected; nullopt otherwise.
std::optional<std::array<int64_t, 3>> parse_dims(const std::string& text);
int scalar_type_size(ScalarType t);

}  // namespace isotope
