// From an array in memory (a simulation's field) to a mesh: a sphere of radius 0.6 sampled on a
// 65^3 grid, extracted at full resolution and coarse, both with their topology measured.
#include <cmath>
#include <cstdio>

#include <isotope/isotope.h>

int main(int argc, char** argv) {
  const int n = 65;
  isotope::Volume field;
  field.dims = {n, n, n};
  field.spacing = {2.0 / (n - 1), 2.0 / (n - 1), 2.0 / (n - 1)};
  field.origin = {-1, -1, -1};
  for (int z = 0; z < n; ++z)
    for (int y = 0; y < n; ++y)
      for (int x = 0; x < n; ++x) {
        const double px = -1 + 2.0 * x / (n - 1), py = -1 + 2.0 * y / (n - 1), pz = -1 + 2.0 * z / (n - 1);
        field.values.push_back(static_cast<float>(0.6 - std::sqrt(px * px + py * py + pz * pz)));  // > 0 inside
      }

  const isotope::Source sphere = isotope::open_volume(std::move(field));
  isotope::ExtractOptions o;  // iso 0, eps 0: full resolution
  const isotope::Mesh full = sphere.extract(o);
  o.eps = 0.01;  // the coarse field deviates from the data by at most 0.01 (data units)
  const isotope::Mesh coarse = sphere.extract(o);
  if (argc > 1) isotope::write_ply(coarse, argv[1]);

  const isotope::MeshTopology f = isotope::measure_topology(full), c = isotope::measure_topology(coarse);
  std::printf("full: %lld triangles; coarse (eps 0.01): %lld triangles; components %lld / %lld, Euler %lld / %lld\n",
              static_cast<long long>(f.triangles), static_cast<long long>(c.triangles),
              static_cast<long long>(f.components), static_cast<long long>(c.components),
              static_cast<long long>(f.euler_characteristic), static_cast<long long>(c.euler_characteristic));
  // A sphere: one closed component, Euler characteristic 2, at either resolution.
  return f.components == 1 && c.components == 1 && f.euler_characteristic == 2 && c.euler_characteristic == 2 &&
                 c.triangles < f.triangles
             ? 0
             : 1;
}
