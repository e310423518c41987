#pragma once
// An indexed, welded triangle mesh in physical coordinates.
#include <array>
#include <cstdint>
#include <vector>

namespace isotope {

struct Mesh {
  std::vector<std::array<float, 3>> positions;
  std::vector<std::array<uint32_t, 3>> triangles;  // counter-clockwise seen from the outside (value <= iso)
};

}  // namespace isotope
