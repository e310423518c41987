#pragma once
// Synthetic volumes with known isosurfaces, for the demo, tests and benchmarks.
#include <array>
#include <cstdint>

#include "isotope/volume.h"

namespace isotope {

// The paper's Table-1 function f = sqrt(x^2+y^2) - (x/2 + y/2 - z + 0.01)^2 on [-1,1]^3,
// evaluated at (p - shift); size nodes per axis.
Volume generate_algebraic(int64_t size, std::array<double, 3> shift = {0, 0, 0});
// That function at one point (isotope bench --scale samples it slab by slab, as uint8).
double algebraic_function(double x, double y, double z);
// Signed fields whose isosurface at 0 is the named shape, positive inside (value > iso = inside).
Volume generate_sphere(int64_t size);          // one sphere: 1 component, chi 2
Volume generate_torus(int64_t size);           // one torus: 1 component, chi 0
Volume generate_linked_tori(int64_t size);     // two linked tori: 2 components, chi 0
Volume generate_nested_spheres(int64_t size);  // a hollow shell with a ball inside: 3 components, chi 6
// A smooth random field in [-1, 1] (sum of random Gaussians), reproducible from the seed.
Volume generate_noise(int64_t size, uint64_t seed, int bumps = 24);

}  // namespace isotope
