#include "engine/core/volume_check.h"

#include <cmath>
#include <cstdint>
#include <stdexcept>
#include <string>

namespace isotope {

void validate_volume(const Volume& volume) {
  for (int64_t d : volume.dims)
    if (d < 2 || d > (int64_t{1} << 19) + 1)
      throw std::invalid_argument("volume dimensions must be 2 .. 524289 nodes per axis");
  if (static_cast<int64_t>(volume.size()) != volume.node_count())
    throw std::invalid_argument("volume holds " + std::to_string(volume.size()) + " values, its dimensions need " +
                                std::to_string(volume.node_count()));
  const float* values = volume.data();
  for (size_t i = 0; i < volume.size(); ++i)
    if (!std::isfinite(values[i])) throw std::invalid_argument("volume value " + std::to_string(i) + " is not finite");
}

}  // namespace isotope
