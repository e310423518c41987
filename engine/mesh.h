#pragma once
// An indexed, welded triangle mesh in physical coordinates.
#include <array>
#include <cstdint>
#include <vector>

#include "engine/huge_page_allocator.h"

namespace isotope {

struct Mesh {
  template <class T>
  using Array = std::vector<T, HugePageAllocator<T>>;  // meshes run to hundreds of megabytes
  Array<std::array<float, 3>> positions;
  Array<std::array<uint32_t, 3>> triangles;  // counter-clockwise seen from the outside (value <= iso)
};

}  // namespace isotope
