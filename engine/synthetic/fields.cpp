// Synthetic volumes on [-1,1]^3 with known isosurfaces (generate_algebraic, generate_sphere and the rest).
// Node (i,j,k) of a size^3 grid sits at p = -1 + 2*(i,j,k)/(size-1), so spacing and origin
// make the mesh coordinates those of the paper's Table-1 domain.
#include "engine/synthetic/fields.h"

#include <algorithm>
#include <cmath>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

#include "engine/core/huge_blocks.h"
#include "engine/core/parallel.h"
#include "isotope/error.h"

namespace isotope {
namespace {

using Point = std::array<double, 3>;

double norm(double x, double y, double z) { return std::sqrt(x * x + y * y + z * z); }

// The position on [-1, 1] of node i of a grid of spacing h.
double grid_coordinate(double h, int64_t i) { return -1.0 + h * static_cast<double>(i); }

// A size^3 volume on [-1, 1]^3, its values not yet set.
Volume grid(int64_t size) {
  if (size < 2) {
    throw InvalidInput("synthetic field: size must be at least 2, got " + std::to_string(size));
  }
  Volume v;
  v.dims = {size, size, size};
  const double h = 2.0 / static_cast<double>(size - 1);
  v.spacing = {h, h, h};
  v.origin = {-1.0, -1.0, -1.0};
  detail::resize_prefaulted_in_parallel(v.values, static_cast<size_t>(v.node_count()));  // written whole below
  return v;
}

// Fills a size^3 volume with f(p) at the physical position p of each node.
template <class Field>
Volume sample(int64_t size, Field f) {
  Volume v = grid(size);
  const double h = v.spacing[0];
  // Slices are independent.
  parallel_for(0, size, [&](int64_t k) {
    const double z = grid_coordinate(h, k);
    for (int64_t j = 0; j < size; ++j) {
      const double y = grid_coordinate(h, j);
      for (int64_t i = 0; i < size; ++i) {
        const double x = grid_coordinate(h, i);
        v.values[v.index(i, j, k)] = static_cast<float>(f(Point{x, y, z}));
      }
    }
  });
  return v;
}

// Torus around the circle of radius big_r centred at c in the plane normal to `axis`;
// positive inside the tube of radius small_r.
double torus(const Point& p, const Point& c, int axis, double big_r, double small_r) {
  const double d[3] = {p[0] - c[0], p[1] - c[1], p[2] - c[2]};
  const int a = (axis + 1) % 3, b = (axis + 2) % 3;
  const double in_plane = std::sqrt(d[a] * d[a] + d[b] * d[b]) - big_r;
  return small_r - std::sqrt(in_plane * in_plane + d[axis] * d[axis]);
}

// A double in [0, 1) from the raw 64-bit output: the same on every standard library,
// unlike std::uniform_real_distribution.
double unit(std::mt19937_64& rng) { return static_cast<double>(rng() >> 11) * 0x1.0p-53; }

}  // namespace

double algebraic_function(double x, double y, double z) {
  const double s = x / 2 + y / 2 - z + 0.01;
  return std::sqrt(x * x + y * y) - s * s;
}

Volume generate_algebraic(int64_t size, std::array<double, 3> shift) {
  return sample(
      size, [shift](const Point& p) { return algebraic_function(p[0] - shift[0], p[1] - shift[1], p[2] - shift[2]); });
}

Volume generate_sphere(int64_t size) {
  return sample(size, [](const Point& p) { return 0.6 - norm(p[0], p[1], p[2]); });
}

Volume generate_torus(int64_t size) {
  return sample(size, [](const Point& p) { return torus(p, {0, 0, 0}, 2, 0.5, 0.2); });
}

// Centres 0.4 apart with R = 0.4: each core circle passes through the other's centre, so the
// tori link once; the cores stay 0.4 apart, leaving a gap of 0.16 between the tubes
// (2.5 voxels at size 33) so they never touch at grid resolution.
Volume generate_linked_tori(int64_t size) {
  return sample(size, [](const Point& p) {
    return std::max(torus(p, {-0.2, 0, 0}, 2, 0.4, 0.12), torus(p, {0.2, 0, 0}, 1, 0.4, 0.12));
  });
}

// Shell 0.4 < |p| < 0.75 (two surfaces) and a ball |p| < 0.2: 3 spheres, chi 6.
Volume generate_nested_spheres(int64_t size) {
  return sample(size, [](const Point& p) {
    const double r = norm(p[0], p[1], p[2]);
    return std::max(std::min(r - 0.4, 0.75 - r), 0.2 - r);
  });
}

Volume generate_noise(int64_t size, uint64_t seed, int bumps) {
  if (bumps < 1) throw InvalidInput("noise field: bumps must be at least 1");
  struct Bump {
    Point centre;
    double inv_two_width_sq, amplitude;
  };
  std::mt19937_64 rng(seed);
  std::vector<Bump> list(static_cast<size_t>(bumps));
  for (Bump& b : list) {
    for (double& c : b.centre) c = -1.0 + 2.0 * unit(rng);
    const double width = 0.15 + 0.25 * unit(rng);
    b.inv_two_width_sq = 1.0 / (2.0 * width * width);
    const double magnitude = 0.5 + 0.5 * unit(rng);
    b.amplitude = (rng() >> 63) != 0 ? -magnitude : magnitude;
  }
  // A Gaussian is the product of one per axis, so a node costs a multiply-add per bump, not an
  // exp (a 513^3 field took 17 s on two cores as 3 billion exps). The x factors are one table
  // shared by the slices, bumps x size doubles: at the most bumps the command takes, never more
  // than the volume itself from 448^3 on, and at most 358 MB below. The y and z factors are taken per row
  // and per slice, a 1/size share of the work. Summed in bump order on every thread: the field
  // does not depend on them.
  Volume v = grid(size);
  const double h = v.spacing[0];
  const auto n = static_cast<size_t>(size);
  const size_t count = list.size();
  const auto factor = [&](size_t bump, int axis, int64_t node) {
    const double d = grid_coordinate(h, node) - list[bump].centre[static_cast<size_t>(axis)];
    return std::exp(-d * d * list[bump].inv_two_width_sq);
  };
  std::vector<double> x_factor(count * n);  // [bump][i]
  parallel_for(0, static_cast<int64_t>(count), [&](int64_t b) {
    for (size_t i = 0; i < n; ++i) {
      x_factor[static_cast<size_t>(b) * n + i] = factor(static_cast<size_t>(b), 0, static_cast<int64_t>(i));
    }
  });
  parallel_for(0, size, [&](int64_t k) {
    std::vector<double> z_factor(count), row(n);
    for (size_t b = 0; b < count; ++b) z_factor[b] = factor(b, 2, k);
    for (int64_t j = 0; j < size; ++j) {
      std::fill(row.begin(), row.end(), 0.0);
      for (size_t b = 0; b < count; ++b) {
        const double c = list[b].amplitude * factor(b, 1, j) * z_factor[b];
        const double* x = x_factor.data() + b * n;
        for (size_t i = 0; i < n; ++i) row[i] += c * x[i];
      }
      float* out = v.values.data() + v.index(0, j, k);
      for (size_t i = 0; i < n; ++i) out[i] = static_cast<float>(row[i]);
    }
  });
  // Affine map of [min, max] onto [-1, 1]; a constant field (not reachable in practice) stays 0.
  const auto [lo_it, hi_it] = std::minmax_element(v.values.begin(), v.values.end());
  const double lo = *lo_it, hi = *hi_it;
  for (float& x : v.values) {
    x = hi > lo ? static_cast<float>(std::clamp(2.0 * (x - lo) / (hi - lo) - 1.0, -1.0, 1.0)) : 0.0f;
  }
  return v;
}

}  // namespace isotope
