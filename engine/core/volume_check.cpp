#include "engine/core/volume_check.h"

#include <cfloat>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <stdexcept>
#include <string>

namespace isotope {
namespace {

std::string triple(const std::array<double, 3>& v) {
  char text[96];
  std::snprintf(text, sizeof text, "(%g, %g, %g)", v[0], v[1], v[2]);
  return text;
}

}  // namespace

void validate_dims(const std::array<int64_t, 3>& dims) {
  for (int64_t d : dims)
    if (d < 2 || d > (int64_t{1} << 19) + 1)
      throw std::invalid_argument("volume dimensions " + std::to_string(dims[0]) + "x" + std::to_string(dims[1]) + "x" +
                                  std::to_string(dims[2]) + " (x by y by z): every axis needs 2 .. 524289 nodes");
}

void validate_layout(const std::array<int64_t, 3>& dims, const std::array<double, 3>& spacing,
                     const std::array<double, 3>& origin) {
  validate_dims(dims);
  for (double s : spacing)
    if (!std::isfinite(s) || !(s > 0))
      throw std::invalid_argument("spacing " + triple(spacing) + " must be 3 finite numbers > 0 (x, y, z)");
  for (double o : origin)
    if (!std::isfinite(o))
      throw std::invalid_argument("origin " + triple(origin) + " must be 3 finite numbers (x, y, z)");
  // Vertices are float32 (isotope/mesh.h): the box's far corner must be one.
  std::array<double, 3> corner{};
  for (int a = 0; a < 3; ++a) corner[a] = origin[a] + spacing[a] * static_cast<double>(dims[a] - 1);
  for (int a = 0; a < 3; ++a)
    if (!(std::fabs(corner[a]) <= FLT_MAX) || !(std::fabs(origin[a]) <= FLT_MAX))
      throw std::invalid_argument("spacing " + triple(spacing) + " and origin " + triple(origin) +
                                  " put the volume's far corner at " + triple(corner) +
                                  ", beyond the mesh's float32 coordinates (about 3.4e38)");
}

void validate_volume(const Volume& volume) {
  validate_layout(volume.dims, volume.spacing, volume.origin);
  if (static_cast<int64_t>(volume.size()) != volume.node_count())
    throw std::invalid_argument("volume holds " + std::to_string(volume.size()) + " values, its dimensions need " +
                                std::to_string(volume.node_count()));
  const float* values = volume.data();
  for (size_t i = 0; i < volume.size(); ++i)
    if (!std::isfinite(values[i])) {
      const auto n = static_cast<size_t>(volume.dims[0]), m = static_cast<size_t>(volume.dims[1]);
      char text[160];
      std::snprintf(text, sizeof text, "volume value %g at (x,y,z) = (%zu,%zu,%zu) is not finite", values[i], i % n,
                    i / n % m, i / (n * m));
      throw std::invalid_argument(text);
    }
}

}  // namespace isotope
