#include <algorithm>
#include <cmath>

#include "engine/core/parallel.h"
#include "isotope/mesh.h"

namespace isotope {

// On all threads, the same bits on any number: the vertices are split into one range per thread,
// and each thread walks every triangle in order and sums the normals of those that touch its
// range. A vertex's sum thus adds its triangles' normals in triangle order, as one walk does; a
// triangle that spans two ranges is computed in both, the same way. The walk over the indices is
// cheap next to the sums, which the ranges share out.
std::vector<std::array<float, 3>> vertex_normals(const Mesh& mesh) {
  const auto n = static_cast<int64_t>(mesh.positions.size());
  std::vector<std::array<float, 3>> normals(static_cast<size_t>(n), {0, 0, 0});
  const int64_t ranges = std::clamp<int64_t>(n / 4096, 1, thread_count());
  parallel_for(int64_t{0}, ranges, [&](int64_t r) {
    const auto lo = static_cast<uint64_t>(n * r / ranges), hi = static_cast<uint64_t>(n * (r + 1) / ranges);
    const auto in_range = [&](uint32_t i) { return i >= lo && i < hi; };
    std::vector<std::array<double, 3>> sum(hi - lo, {0, 0, 0});
    for (const auto& t : mesh.triangles) {
      if (!in_range(t[0]) && !in_range(t[1]) && !in_range(t[2])) continue;
      const auto& a = mesh.positions[t[0]];
      const auto& b = mesh.positions[t[1]];
      const auto& c = mesh.positions[t[2]];
      const double u[3] = {double(b[0]) - a[0], double(b[1]) - a[1], double(b[2]) - a[2]};
      const double v[3] = {double(c[0]) - a[0], double(c[1]) - a[1], double(c[2]) - a[2]};
      const double m[3] = {u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]};
      for (const uint32_t i : t)
        if (in_range(i))
          for (int k = 0; k < 3; ++k) sum[i - lo][k] += m[k];
    }
    for (uint64_t i = lo; i < hi; ++i) {
      const auto& s = sum[i - lo];
      const double len = std::sqrt(s[0] * s[0] + s[1] * s[1] + s[2] * s[2]);
      if (len > 0)
        for (int k = 0; k < 3; ++k) normals[i][k] = static_cast<float>(s[k] / len);
    }
  });
  return normals;
}

}  // namespace isotope
