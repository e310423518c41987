#include <cmath>

#include "isotope/mesh.h"

namespace isotope {

std::vector<std::array<float, 3>> vertex_normals(const Mesh& mesh) {
  std::vector<std::array<double, 3>> sum(mesh.positions.size(), {0, 0, 0});
  for (const auto& t : mesh.triangles) {
    const auto& a = mesh.positions[t[0]];
    const auto& b = mesh.positions[t[1]];
    const auto& c = mesh.positions[t[2]];
    const double u[3] = {double(b[0]) - a[0], double(b[1]) - a[1], double(b[2]) - a[2]};
    const double v[3] = {double(c[0]) - a[0], double(c[1]) - a[1], double(c[2]) - a[2]};
    const double n[3] = {u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]};
    for (const uint32_t i : t)
      for (int k = 0; k < 3; ++k) sum[i][k] += n[k];
  }
  std::vector<std::array<float, 3>> normals(sum.size(), {0, 0, 0});
  for (size_t i = 0; i < sum.size(); ++i) {
    const double len = std::sqrt(sum[i][0] * sum[i][0] + sum[i][1] * sum[i][1] + sum[i][2] * sum[i][2]);
    if (len > 0)
      for (int k = 0; k < 3; ++k) normals[i][k] = static_cast<float>(sum[i][k] / len);
  }
  return normals;
}

}  // namespace isotope
