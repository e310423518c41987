// Controlled topology simplification (paper Sec. 5): delta = 0 is preserve, a delta above every
// weight is none, triangles fall as delta grows, and every topology change is explained by a
// critical point whose weight is under delta, on fields with features of known size.
#include <gtest/gtest.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <limits>
#include <optional>
#include <random>
#include <string>
#include <vector>

#include "engine/diagnostics/component_report.h"
#include "engine/extract/extract_drivers.h"
#include "engine/hierarchy/diamond.h"
#include "engine/hierarchy/multires_volume.h"
#include "engine/hierarchy/record_builder.h"
#include "engine/synthetic/fields.h"
#include "isotope/mesh.h"
#include "tests/support/test_support.h"

namespace isotope {
namespace {

using testing::make_volume;
using testing::triangle_set;

constexpr SimplificationWeight kWeights[] = {SimplificationWeight::interval, SimplificationWeight::gradient,
                                             SimplificationWeight::size};

// The largest weight of any record: a delta above it drops every critical point.
float max_weight(const MultiresVolume& mv, SimplificationWeight w) {
  float m = 0;
  const int64_t n = mv.lattice().n;
  for (int64_t z = 0; z <= n; ++z)
    for (int64_t y = 0; y <= n; ++y)
      for (int64_t x = 0; x <= n; ++x) {
        const Coord v{x, y, z};
        if ((x == 0 || x == n) && (y == 0 || y == n) && (z == 0 || z == n)) continue;  // corners: none
        if (!mv.has_record(v)) continue;
        m = std::max(m, mv.topology(mv.record_slot(v)).weight[static_cast<size_t>(w)]);
      }
  return m;
}

ExtractOptions options(float iso, double eps, TopologyMode mode, double delta = 0,
                       SimplificationWeight w = SimplificationWeight::interval) {
  ExtractOptions o;
  o.iso = iso;
  o.eps = eps;
  o.topology = mode;
  o.delta = delta;
  o.weight = w;
  return o;
}

// Fields on [-1, 1]^3 sampled at 65^3 nodes (spacing 1/32), positive inside.
constexpr int64_t kSize = 65;
template <class F>
Volume sample_field(F f) {
  return make_volume({kSize, kSize, kSize}, [&](int64_t x, int64_t y, int64_t z) {
    const double h = 2.0 / (kSize - 1);
    return f(-1 + h * static_cast<double>(x), -1 + h * static_cast<double>(y), -1 + h * static_cast<double>(z));
  });
}

double len(double x, double y, double z) { return std::sqrt(x * x + y * y + z * z); }

// Fields with features of known size (values -0.1 or -0.3 far from everything).
// A sphere of radius 0.45, a small Gaussian blob of peak 0.05 above the isovalue 0 (weight ~0.15:
// it rises 0.15 above the background) and a large one of peak 0.4 (weight ~0.5), far apart.
Volume sphere_with_blobs() {
  return sample_field([](double x, double y, double z) {
    const double sphere = std::max(0.45 - len(x, y, z), -0.1);
    const double small = -0.1 + 0.15 * std::exp(-std::pow(len(x - 0.75, y - 0.75, z - 0.75), 2) / 0.005);
    const double big = -0.1 + 0.5 * std::exp(-std::pow(len(x + 0.75, y + 0.75, z - 0.75), 2) / 0.005);
    return std::max({sphere, small, big});
  });
}
// Two balls of radius 0.4 at x = +-0.55 joined by a neck of radius 0.025 (under a voxel) on a
// line of odd lattice nodes, which coarse levels do not sample.
Volume two_spheres_with_neck() {
  return sample_field([](double x, double y, double z) {
    const double s1 = 0.4 - len(x - 0.55, y, z), s2 = 0.4 - len(x + 0.55, y, z);
    const double neck = std::min(0.025 - std::hypot(y - 1.0 / 32, z - 1.0 / 32), 0.55 - std::fabs(x));
    return std::max({s1, s2, neck, -0.1});
  });
}
// Two tori (major radius 0.3, tube 0.12) at x = -0.5 and x = +0.5; the one at +0.5 thins to a
// tube of 0.02 (under a voxel) on its far side: a thin handle.
Volume thick_and_thin_handled_tori() {
  return sample_field([](double x, double y, double z) {
    auto torus = [&](double cx, double thin) {
      const double theta = std::atan2(y, x - cx);
      const double r = thin + (0.12 - thin) * std::min(1.0, std::fabs(theta) / 0.8);
      return r - std::hypot(std::hypot(x - cx, y) - 0.3, z);
    };
    return std::max({torus(-0.5, 0.12), torus(0.5, 0.02), -0.3});
  });
}

struct Case {
  std::string name;
  Volume volume;
  std::vector<float> isovalues;
  std::vector<double> eps;
};

// Synthetic fields and real volumes, each with isovalues and eps from fine to coarse.
const std::vector<Case>& cases() {
  static const std::vector<Case> all = [] {
    std::vector<Case> c;
    c.push_back({"noise 33 seed 3", generate_noise(33, 3), {-0.2f, 0.1f}, {0.02, 0.1, 0.4}});
    c.push_back({"noise 33 seed 8", generate_noise(33, 8, 48), {0.0f, 0.2f}, {0.02, 0.1, 0.4}});
    c.push_back({"algebraic 33", generate_algebraic(33), {0.0f}, {1.0 / 64, 1.0 / 16, 0.25}});
    c.push_back({"blobs", sphere_with_blobs(), {0.0f}, {0.2, 0.8, 3}});
    c.push_back({"neck", two_spheres_with_neck(), {0.0f}, {0.1, 0.2}});
    c.push_back({"tori", thick_and_thin_handled_tori(), {0.0f}, {0.2, 0.8}});
    for (const auto& shared : testing::shared_volumes()) {
      if (shared.name != "neghip" && shared.name != "hydrogen") continue;
      const float range = shared.name == "hydrogen" ? 1.0f : 255.0f;
      c.push_back({shared.name,
                   testing::load_shared(shared),
                   {shared.isovalues[0], shared.isovalues[1]},
                   {0.01 * range, 0.05 * range, 0.2 * range}});
    }
    return c;
  }();
  return all;
}

// Calls f(case name, volume, weight, the volume's largest weight of that kind, iso, eps) for every
// case, weight, isovalue and eps.
template <class F>
void for_each_setting(F f) {
  for (const Case& c : cases()) {
    const MultiresVolume mv = MultiresVolume::build(c.volume);
    for (SimplificationWeight w : kWeights) {
      const double top = max_weight(mv, w);
      ASSERT_GT(top, 0) << c.name << " has no critical point";
      for (float iso : c.isovalues)
        for (double eps : c.eps)
          f(c.name + " iso " + std::to_string(iso) + " eps " + std::to_string(eps), mv, w, top, iso, eps);
    }
  }
}

// The gradient weight as docs/METHOD.md defines it, computed the plain way: per tetrahedron
// (end, v, r_i, r_i+1), Cramer's rule with a division per component and a root per tetrahedron.
LocalWeights plain_local_weights(const DiamondValues& dv, const DiamondShape& s, IsoInterval x) {
  LocalWeights w;
  for (int e = 0; e < 2; ++e) {
    const double fe = e == 0 ? dv.fa : dv.fb;
    const auto& pe = s.offset[static_cast<size_t>(e)];
    for (int i = 0; i < s.ring_count; ++i) {
      const int i1 = (i + 1) % s.ring_count;
      if ((s.real_ring >> i & 1u) == 0 || (s.real_ring >> i1 & 1u) == 0) continue;
      const auto& p1 = s.offset[static_cast<size_t>(2 + i)];
      const auto& p2 = s.offset[static_cast<size_t>(2 + i1)];
      const double f1 = dv.ring[i], f2 = dv.ring[i1], fv = dv.fv;
      const double m[3][3] = {{double(pe[0]), double(pe[1]), double(pe[2])},
                              {double(p1[0]), double(p1[1]), double(p1[2])},
                              {double(p2[0]), double(p2[1]), double(p2[2])}};
      const double r[3] = {fe - fv, f1 - fv, f2 - fv};
      auto det3 = [](const double(&a)[3][3]) {
        return a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1]) - a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0]) +
               a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0]);
      };
      const double det = det3(m);
      if (det == 0) continue;
      double g2 = 0;
      for (int c = 0; c < 3; ++c) {
        double mc[3][3];
        for (int row = 0; row < 3; ++row)
          for (int col = 0; col < 3; ++col) mc[row][col] = col == c ? r[row] : m[row][col];
        const double gc = det3(mc) / det;
        g2 += gc * gc;
      }
      w.gradient = std::max(w.gradient, std::sqrt(g2));
      const double lo = std::min({fe, fv, f1, f2}), hi = std::max({fe, fv, f1, f2});
      if (std::max(lo, double(x.lo)) < std::min(hi, double(x.hi))) w.size += s.child_tets;
    }
  }
  return w;
}

// local_weights takes the gradient from each shape's exact inverse where the values are small
// integers, Cramer's quotients by an exact reciprocal otherwise: both must give the plain
// computation's bits, on every shape of every class and scale (cut diamonds at the faces
// included), for 8-bit, 24-bit, fractional and wide-ranging values.
TEST(LocalWeights, EveryShapeGivesThePlainComputationsBits) {
  const Lattice l = Lattice::enclosing({65, 65, 65});
  std::mt19937 rng(11);
  int compared = 0, shapes = 0, inverse_shapes = 0;
  for (int64_t z = 0; z <= l.n; ++z)
    for (int64_t y = 0; y <= l.n; ++y)
      for (int64_t x = 0; x <= l.n; ++x) {
        const Coord v{x, y, z};
        // A sample of the lattice's vertices: every scale, every class, the faces.
        if (scale_of(v, l) >= l.k || (x + 3 * y + 7 * z) % 29 != 0) continue;
        const Diamond d = diamond_of(v, l);
        const DiamondShape shape = shape_of(d, l);
        const ShapeGradients gradients = gradients_of(shape);
        ++shapes;
        inverse_shapes += gradients.inverse ? 1 : 0;
        for (int kind = 0; kind < 4; ++kind) {
          DiamondValues dv;
          dv.type = d.type;
          auto value = [&]() -> float {
            switch (kind) {
              case 0: return static_cast<float>(rng() % 256);
              case 1: return static_cast<float>(static_cast<int32_t>(rng() % (1u << 25)) - (1 << 24));
              case 2: return std::uniform_real_distribution<float>(-1, 1)(rng);
              default:
                return std::ldexp(std::uniform_real_distribution<float>(-1, 1)(rng), static_cast<int>(rng() % 80) - 40);
            }
          };
          dv.fa = value();
          dv.fb = value();
          dv.fv = value();
          for (int i = 0; i < d.ring_count; ++i) dv.ring[i] = value();
          const IsoInterval x_all{-std::numeric_limits<float>::max(), std::numeric_limits<float>::max()};
          for (const IsoInterval& iv : {x_all, IsoInterval{dv.fv, dv.fv + 1}}) {
            const LocalWeights want = plain_local_weights(dv, shape, iv);
            for (const LocalWeights& got : {local_weights(dv, shape, iv), local_weights(dv, shape, iv, &gradients)}) {
              ASSERT_EQ(std::bit_cast<uint64_t>(got.gradient), std::bit_cast<uint64_t>(want.gradient))
                  << "vertex " << x << " " << y << " " << z << " values of kind " << kind;
              ASSERT_EQ(std::bit_cast<uint64_t>(got.size), std::bit_cast<uint64_t>(want.size));
            }
            ++compared;
          }
        }
      }
  EXPECT_GT(compared, 500);
  // Every shape of this lattice has power-of-two determinants: the exact inverse is what runs.
  EXPECT_EQ(inverse_shapes, shapes);
}

// At the exact inverse's limits: offsets of 2^12 lattice steps (scale 12, an 8193^3 lattice) with
// values of magnitude 2^24, where every sum is still exact; and beyond them (scale 13 of a
// 16385^3 lattice), where the shape has no exact inverse and Cramer's quotients run.
TEST(LocalWeights, TheLargestShapesGiveThePlainComputationsBits) {
  std::mt19937 rng(5);
  for (int k : {13, 14}) {
    const int64_t n = int64_t{1} << k;
    const Lattice l = Lattice::enclosing({n + 1, n + 1, n + 1});
    const int64_t s = n / 2;  // scale k - 1: the largest with records
    for (const Coord& v : std::vector<Coord>{{s, 0, 0}, {s, s, 0}, {s, s, s}, {0, s, n}, {n, s, s}, {s, 0, s}}) {
      ASSERT_EQ(scale_of(v, l), k - 1);
      const Diamond d = diamond_of(v, l);
      const DiamondShape shape = shape_of(d, l);
      const ShapeGradients gradients = gradients_of(shape);
      EXPECT_EQ(gradients.inverse, k == 13) << "scale " << k - 1;
      for (int trial = 0; trial < 200; ++trial) {
        DiamondValues dv;
        dv.type = d.type;
        auto value = [&]() -> float {
          const int32_t extreme = trial % 3 == 0 ? (1 << 24) : trial % 3 == 1 ? -(1 << 24) : 0;
          return static_cast<float>(extreme != 0 && rng() % 2 ? extreme
                                                              : static_cast<int32_t>(rng() % (1u << 25)) - (1 << 24));
        };
        dv.fa = value();
        dv.fb = value();
        dv.fv = value();
        for (int i = 0; i < d.ring_count; ++i) dv.ring[i] = value();
        const IsoInterval all{-std::numeric_limits<float>::max(), std::numeric_limits<float>::max()};
        const LocalWeights want = plain_local_weights(dv, shape, all), got = local_weights(dv, shape, all, &gradients);
        ASSERT_EQ(std::bit_cast<uint64_t>(got.gradient), std::bit_cast<uint64_t>(want.gradient)) << "scale " << k - 1;
        ASSERT_EQ(std::bit_cast<uint64_t>(got.size), std::bit_cast<uint64_t>(want.size));
      }
    }
  }
}

// delta = 0 keeps every critical point: the preserve mesh, bit for bit, for every weight.
TEST(Simplify, DeltaZeroIsPreserve) {
  int compared = 0;
  for_each_setting(
      [&](const std::string& what, const MultiresVolume& mv, SimplificationWeight w, double, float iso, double eps) {
        const Mesh preserve = extract(mv, options(iso, eps, TopologyMode::preserve));
        ExtractStats stats;
        const Mesh simplify = extract(mv, options(iso, eps, TopologyMode::simplify, 0, w), &stats);
        EXPECT_EQ(simplify.triangles, preserve.triangles) << what;
        EXPECT_EQ(simplify.positions, preserve.positions) << what;
        EXPECT_EQ(stats.tets_simplified, 0) << what;
        ++compared;
      });
  EXPECT_GE(compared, 90);
}

// A delta above the largest weight of the volume drops every critical point: the none mesh.
TEST(Simplify, DeltaAboveEveryWeightIsNone) {
  int differs_from_preserve = 0;
  for_each_setting([&](const std::string& what, const MultiresVolume& mv, SimplificationWeight w, double top, float iso,
                       double eps) {
    const double delta = std::nextafter(top, std::numeric_limits<double>::infinity());
    const Mesh none = extract(mv, options(iso, eps, TopologyMode::none));
    const Mesh simplify = extract(mv, options(iso, eps, TopologyMode::simplify, delta, w));
    EXPECT_EQ(simplify.triangles, none.triangles) << what;
    EXPECT_EQ(simplify.positions, none.positions) << what;
    differs_from_preserve += extract(mv, options(iso, eps, TopologyMode::preserve)).triangles != none.triangles;
  });
  EXPECT_GT(differs_from_preserve, 10);  // the cases do exercise topology control
}

// Growing delta drops critical points, so the set of refined tetrahedra shrinks; refining a
// tetrahedron never lowers its triangle count (a cut tetrahedron's two children hold at least its
// triangles), so the count cannot grow. (Clipped at the data box, it could in principle:
// docs/METHOD.md, "Controlled topology simplification"; these volumes never show it.) Checked over deltas from 2^-12 of
// the largest weight to 4 times it, in factors of 4.
TEST(Simplify, TrianglesFallAsDeltaGrows) {
  int steps = 0, falls = 0;
  for_each_setting([&](const std::string& what, const MultiresVolume& mv, SimplificationWeight w, double top, float iso,
                       double eps) {
    size_t previous = extract(mv, options(iso, eps, TopologyMode::preserve)).triangles.size();
    for (int k = 12; k >= -2; k -= 2) {
      const double delta = std::ldexp(top, -k);
      const size_t t = extract(mv, options(iso, eps, TopologyMode::simplify, delta, w)).triangles.size();
      EXPECT_LE(t, previous) << what << " " << to_string(w) << " delta " << delta;
      falls += t < previous;
      previous = t;
      ++steps;
    }
    EXPECT_EQ(previous, extract(mv, options(iso, eps, TopologyMode::none)).triangles.size()) << what;
  });
  EXPECT_GT(falls, 20);
  EXPECT_GT(steps, 700);
}

// Every difference from preserve is explained by dropped critical points: a simplify mesh in which
// no tetrahedron stopped for a weight under delta (tets_simplified = 0) is the preserve mesh, and
// a change of components or Euler characteristic always comes with such tetrahedra.
TEST(Simplify, EveryTopologyChangeIsExplainedByADroppedCriticalPoint) {
  int topology_changes = 0, unchanged = 0;
  for_each_setting([&](const std::string& what, const MultiresVolume& mv, SimplificationWeight w, double top, float iso,
                       double eps) {
    const Mesh preserve = extract(mv, options(iso, eps, TopologyMode::preserve));
    const MeshTopology p = measure_topology(preserve);
    for (int k = 8; k >= 0; k -= 2) {
      ExtractStats stats;
      const Mesh m = extract(mv, options(iso, eps, TopologyMode::simplify, std::ldexp(top, -k), w), &stats);
      const MeshTopology t = measure_topology(m);
      if (stats.tets_simplified == 0) {
        EXPECT_EQ(m.triangles, preserve.triangles) << what;
        ++unchanged;
      }
      if (t.components != p.components || t.euler_characteristic != p.euler_characteristic) {
        EXPECT_GT(stats.tets_simplified, 0) << what;
        ++topology_changes;
      }
    }
  });
  EXPECT_GT(topology_changes, 20);
  EXPECT_GT(unchanged, 20);
}

// The component whose bounding box is centred within 10 voxels of p (the closest), or -1. Not
// "whose box contains p": a coarse mesh's boxes are loose.
int component_at(const std::vector<ComponentStats>& components, std::array<double, 3> p) {
  int best = -1;
  double best_distance = 10;
  for (size_t i = 0; i < components.size(); ++i) {
    const ComponentStats& c = components[i];
    double d2 = 0;
    for (int a = 0; a < 3; ++a) d2 += std::pow(0.5 * (c.bbox_min[a] + c.bbox_max[a]) - p[a], 2);
    if (std::sqrt(d2) < best_distance) best = static_cast<int>(i), best_distance = std::sqrt(d2);
  }
  return best;
}

// Grid coordinates of a point of [-1, 1]^3 (the meshes are in node units: spacing 1, origin 0).
std::array<double, 3> at(double x, double y, double z) { return {(x + 1) * 32, (y + 1) * 32, (z + 1) * 32}; }

TEST(SimplifyFeatures, NoiseBlobsBelowDeltaGoAndLargerOnesStay) {
  const MultiresVolume mv = MultiresVolume::build(sphere_with_blobs());
  const auto sphere = at(0, 0, 0), small = at(0.75, 0.75, 0.75), big = at(-0.75, -0.75, 0.75);
  const double eps = 3;  // coarse enough that without topology control nothing is left
  EXPECT_EQ(extract(mv, options(0, eps, TopologyMode::none)).triangles.size(), 0u);
  const auto components = [&](double delta, SimplificationWeight w) {
    return measure_components(extract(mv, options(0, eps, TopologyMode::simplify, delta, w)));
  };
  auto kept = measure_components(extract(mv, options(0, eps, TopologyMode::preserve)));
  ASSERT_EQ(kept.size(), 3u);
  for (const auto& p : {sphere, small, big}) EXPECT_GE(component_at(kept, p), 0);
  // Interval weight: the small blob rises 0.15 above its surroundings, the big one 0.5, the sphere 0.55.
  EXPECT_EQ(components(0.1, SimplificationWeight::interval), kept);
  auto c = components(0.2, SimplificationWeight::interval);
  ASSERT_EQ(c.size(), 2u);
  EXPECT_EQ(component_at(c, small), -1);
  EXPECT_GE(component_at(c, big), 0);
  EXPECT_GE(component_at(c, sphere), 0);
  EXPECT_EQ(components(0.45, SimplificationWeight::interval).size(), 2u);
  EXPECT_EQ(components(0.6, SimplificationWeight::interval).size(), 0u);
  // Size weight: both blobs are small (a few voxels across), the sphere is not.
  c = components(1e5, SimplificationWeight::size);
  ASSERT_EQ(c.size(), 1u);
  EXPECT_GE(component_at(c, sphere), 0);
  EXPECT_EQ(components(1e3, SimplificationWeight::size).size(), 3u);
}

TEST(SimplifyFeatures, ThinNeckBreaksAboveItsWeight) {
  const MultiresVolume mv = MultiresVolume::build(two_spheres_with_neck());
  const double eps = 0.2;
  const MeshTopology none = measure_topology(extract(mv, options(0, eps, TopologyMode::none)));
  EXPECT_EQ(none.components, 2);  // without topology control the neck is gone
  const MeshTopology preserve = measure_topology(extract(mv, options(0, eps, TopologyMode::preserve)));
  EXPECT_EQ(preserve.components, 1);
  EXPECT_EQ(preserve.euler_characteristic, 2);
  // The neck's critical points weigh about 0.04 (interval): a delta below keeps it.
  const auto kept = measure_components(extract(mv, options(0, eps, TopologyMode::simplify, 0.02)));
  ASSERT_EQ(kept.size(), 1u);
  EXPECT_EQ(kept[0].genus, 0);
  const auto broken = measure_components(extract(mv, options(0, eps, TopologyMode::simplify, 0.1)));
  ASSERT_EQ(broken.size(), 2u);
  for (const ComponentStats& s : broken) EXPECT_EQ(s.genus, 0);
  EXPECT_NE(component_at(broken, at(0.55, 0, 0)), component_at(broken, at(-0.55, 0, 0)));
}

TEST(SimplifyFeatures, ThinHandleClosesWhileTheThickOneStays) {
  const MultiresVolume mv = MultiresVolume::build(thick_and_thin_handled_tori());
  const double eps = 0.8;
  const auto thick = at(-0.5, 0, 0), thin = at(0.5, 0, 0);  // the tori's centres
  const auto genus_at = [&](const std::vector<ComponentStats>& c, std::array<double, 3> p) {
    const int i = component_at(c, p);
    return i < 0 ? std::optional<int64_t>() : c[static_cast<size_t>(i)].genus;
  };
  const auto preserve = measure_components(extract(mv, options(0, eps, TopologyMode::preserve)));
  ASSERT_EQ(preserve.size(), 2u);
  EXPECT_EQ(genus_at(preserve, thick), 1);
  EXPECT_EQ(genus_at(preserve, thin), 1);
  EXPECT_EQ(measure_components(extract(mv, options(0, eps, TopologyMode::simplify, 0.02))), preserve);
  // Above the thin handle's weight (about 0.03) and below the thick torus's.
  const auto simplified = measure_components(extract(mv, options(0, eps, TopologyMode::simplify, 0.06)));
  ASSERT_EQ(simplified.size(), 2u);
  EXPECT_EQ(genus_at(simplified, thick), 1);
  EXPECT_EQ(genus_at(simplified, thin), 0);
  // Above every weight: what no topology control gives (the thick torus falls apart too).
  const Mesh none = extract(mv, options(0, eps, TopologyMode::none));
  EXPECT_EQ(extract(mv, options(0, eps, TopologyMode::simplify, 1.0)).triangles, none.triangles);
  EXPECT_NE(measure_topology(none).euler_characteristic, 0);
}

// The paper's lobster in spirit, on the noisiest shared surface: hydrogen at iso 0.001, 73
// components and Euler characteristic -58 at full resolution. preserve keeps all of them (and the
// comparison with full resolution, which pairs close specks one to one, names no change);
// simplify drops some, and every change it names is one the mesh's counts show.
TEST(SimplifyFeatures, NoisyVolumeComparedWithFullResolution) {
  const auto& shared = testing::shared_volumes();
  const auto it = std::find_if(shared.begin(), shared.end(), [](const auto& v) { return v.name == "hydrogen"; });
  ASSERT_NE(it, shared.end());
  const MultiresVolume mv = MultiresVolume::build(testing::load_shared(*it));
  const float iso = 0.001f;
  const double eps = 0.016, tolerance = 3;
  const Mesh full = extract(mv, options(iso, 0, TopologyMode::none));
  const MeshTopology ft = measure_topology(full);
  EXPECT_GT(ft.components, 50);
  const Mesh preserve = extract(mv, options(iso, eps, TopologyMode::preserve));
  EXPECT_LT(preserve.triangles.size() * 4, full.triangles.size());
  const ComponentComparison p = compare_components(full, preserve, tolerance);
  EXPECT_TRUE(p.changes.empty());
  EXPECT_EQ(p.matched_unchanged.size(), static_cast<size_t>(ft.components));
  const Mesh simplified = extract(mv, options(iso, eps, TopologyMode::simplify, 0.003));
  EXPECT_LT(simplified.triangles.size(), preserve.triangles.size());
  const ComponentComparison c = compare_components(full, simplified, tolerance);
  ASSERT_FALSE(c.changes.empty());
  // The groups account for every component on each side, and their Euler changes for the total.
  size_t full_count = c.matched_unchanged.size(), adaptive_count = c.matched_unchanged.size();
  int64_t euler_change = 0;
  for (const ComponentChange& ch : c.changes) {
    full_count += ch.full.size(), adaptive_count += ch.adaptive.size();
    euler_change += ch.euler_change;
  }
  EXPECT_EQ(full_count, static_cast<size_t>(ft.components));
  EXPECT_EQ(adaptive_count, measure_components(simplified).size());
  EXPECT_EQ(euler_change, measure_topology(simplified).euler_characteristic - ft.euler_characteristic);
}

// A triangle budget in simplify mode without a delta chooses delta too (ExtractOptions::auto_delta):
// the smallest delta whose coarsest mesh takes at most half the budget, then the finest eps within
// all of it. The mesh fits and is the plain simplify mesh at the chosen delta and eps; a larger
// budget never drops more; where preserve cannot fit, this does.
TEST(SimplifyBudget, ChoosesTheSmallestDeltaThatLeavesHalfTheBudget) {
  const Volume v = testing::load_shared(testing::shared_volumes()[2]);  // hydrogen: dozens of small components
  const MultiresVolume mv = MultiresVolume::build(v);
  const float iso = 0.001f;
  ExtractOptions preserve = options(iso, std::numeric_limits<double>::infinity(), TopologyMode::preserve);
  const auto floor = static_cast<int64_t>(extract(mv, preserve).triangles.size());
  ExtractOptions none = options(iso, std::numeric_limits<double>::infinity(), TopologyMode::none);
  const auto none_floor = static_cast<int64_t>(extract(mv, none).triangles.size());
  ASSERT_LT(2 * none_floor, floor) << "features must cost something to keep";
  double last_delta = std::numeric_limits<double>::infinity();
  int below_preserve = 0;
  for (const int64_t budget : {2 * none_floor + 10, floor, 2 * floor, 4 * floor, 20 * floor}) {
    for (const SimplificationWeight w : kWeights) {
      ExtractOptions o = options(iso, 0, TopologyMode::simplify, 0, w);
      o.max_triangles = budget;
      o.auto_delta = true;
      ExtractStats s;
      const Mesh m = extract(mv, o, &s);
      const std::string what = "budget " + std::to_string(budget) + " weight " + std::string(to_string(w));
      EXPECT_LE(static_cast<int64_t>(m.triangles.size()), budget) << what;
      ASSERT_GE(s.chosen_delta, 0) << what;
      EXPECT_LE(s.delta_floor_triangles, budget / 2) << what;
      // The chosen delta and eps, given as they are, make the same mesh.
      ExtractOptions plain = options(iso, s.chosen_eps, TopologyMode::simplify, s.chosen_delta, w);
      plain.eps_ties = s.chosen_eps_ties;
      EXPECT_TRUE(triangle_set(extract(mv, plain)) == triangle_set(m)) << what;
      // And its coarsest mesh is the floor reported.
      plain.eps = std::numeric_limits<double>::infinity();
      plain.eps_ties = -1;
      EXPECT_EQ(static_cast<int64_t>(extract(mv, plain).triangles.size()), s.delta_floor_triangles) << what;
      if (w == SimplificationWeight::interval) {
        EXPECT_LE(s.chosen_delta, last_delta) << what << ": a larger budget drops no more";
        last_delta = s.chosen_delta;
        below_preserve += budget < floor;
      }
    }
  }
  EXPECT_GT(below_preserve, 0) << "a budget preserve refuses was met";
  EXPECT_EQ(last_delta, 0) << "a budget of many times preserve's floor keeps every feature";
  ExtractOptions bad = options(iso, 0, TopologyMode::preserve);
  bad.max_triangles = 1000;
  bad.auto_delta = true;
  EXPECT_THROW(extract(mv, bad), OptionError) << "choosing delta is for simplify mode";
}

}  // namespace
}  // namespace isotope
