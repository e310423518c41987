// Per-component measures (exact on hand-made meshes, within discretisation error on the analytic
// fields) and the full-versus-adaptive comparison on meshes whose change is known by construction.
#include "engine/diagnostics/component_report.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <numeric>
#include <stdexcept>
#include <vector>

#include "engine/extract/extract_drivers.h"
#include "engine/hierarchy/multires_volume.h"
#include "engine/synthetic/fields.h"
#include "tests/support/test_support.h"

namespace isotope {
namespace {

using std::numbers::pi;
using Vec = std::array<double, 3>;

Mesh make_mesh(const std::vector<std::array<float, 3>>& positions,
               const std::vector<std::array<uint32_t, 3>>& triangles) {
  Mesh m;
  m.positions.assign(positions.begin(), positions.end());
  m.triangles.assign(triangles.begin(), triangles.end());
  return m;
}

// The unit cube, vertex x + 2y + 4z at (x, y, z), counter-clockwise seen from outside.
Mesh unit_cube() {
  std::vector<std::array<float, 3>> p;
  for (int i = 0; i < 8; ++i)
    p.push_back({static_cast<float>(i & 1), static_cast<float>((i >> 1) & 1), static_cast<float>((i >> 2) & 1)});
  return make_mesh(p, {{0, 2, 3},
                       {0, 3, 1},
                       {4, 5, 7},
                       {4, 7, 6},
                       {0, 1, 5},
                       {0, 5, 4},
                       {2, 6, 7},
                       {2, 7, 3},
                       {0, 4, 6},
                       {0, 6, 2},
                       {1, 3, 7},
                       {1, 7, 5}});
}

Mesh unit_tetrahedron() {
  return make_mesh({{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}}, {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}});
}

Mesh open_square() { return make_mesh({{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}}, {{0, 1, 2}, {0, 2, 3}}); }

// A 3x3 grid of unit squares in z = 0, without the centre one if `holed` (an annulus, chi 0).
Mesh grid_patch(bool holed) {
  std::vector<std::array<float, 3>> p;
  for (int y = 0; y <= 3; ++y)
    for (int x = 0; x <= 3; ++x) p.push_back({static_cast<float>(x), static_cast<float>(y), 0});
  std::vector<std::array<uint32_t, 3>> t;
  for (uint32_t y = 0; y < 3; ++y)
    for (uint32_t x = 0; x < 3; ++x) {
      if (holed && x == 1 && y == 1) continue;
      const uint32_t a = 4 * y + x;
      t.push_back({a, a + 1, a + 5});
      t.push_back({a, a + 5, a + 4});
    }
  return make_mesh(p, t);
}

Mesh flipped(Mesh m) {
  for (auto& t : m.triangles) std::swap(t[1], t[2]);
  return m;
}

Mesh transformed(Mesh m, double scale, const Vec& shift) {
  for (auto& p : m.positions)
    for (int a = 0; a < 3; ++a) p[a] = static_cast<float>(scale * p[a] + shift[a]);
  return m;
}

Mesh joined(Mesh a, const Mesh& b) {
  const auto base = static_cast<uint32_t>(a.positions.size());
  a.positions.insert(a.positions.end(), b.positions.begin(), b.positions.end());
  for (const auto& t : b.triangles) a.triangles.push_back({t[0] + base, t[1] + base, t[2] + base});
  return a;
}

Mesh sphere_mesh(int64_t size) { return extract_full_resolution(generate_sphere(size), 0.0f); }

// Voxel spacing of the synthetic fields at `size` nodes per axis (on [-1, 1]).
double spacing(int64_t size) { return 2.0 / static_cast<double>(size - 1); }

struct Ball {
  double x, radius;
};
struct Bar {
  double from, to, radius;
};

// Balls and bars on the x axis of a 73x25x25 grid (voxel units, spacing 1, the axis at
// y = z = 12), positive inside; radii keep every node off the isosurface.
Mesh balls_and_bars(const std::vector<Ball>& balls, const std::vector<Bar>& bars) {
  const Volume v = testing::make_volume({73, 25, 25}, [&](int64_t x, int64_t y, int64_t z) {
    const double px = static_cast<double>(x);
    const double off_axis = std::hypot(static_cast<double>(y) - 12, static_cast<double>(z) - 12);
    double f = -1e9;
    for (const Ball& b : balls) f = std::max(f, b.radius - std::hypot(px - b.x, off_axis));
    for (const Bar& b : bars) f = std::max(f, std::min({b.radius - off_axis, px - b.from, b.to - px}));
    return f;
  });
  return extract_full_resolution(v, 0.0f);
}

// Three balls of radius 7.3 at x = 12, 36, 60 (gaps of 9.4 voxels), consecutive ones joined by
// a bar of radius 3.5 where bars[i] is set.
Mesh beads(std::array<bool, 2> bars) {
  std::vector<Bar> list;
  for (size_t i = 0; i < 2; ++i)
    if (bars[i]) list.push_back({12.0 + 24.0 * static_cast<double>(i), 36.0 + 24.0 * static_cast<double>(i), 3.5});
  return balls_and_bars({{12, 7.3}, {36, 7.3}, {60, 7.3}}, list);
}

// generate_torus with its hole filled by a disk |z| < 0.1, radius 0.45: a sphere-like surface
// that agrees with the torus away from the hole.
Mesh filled_torus(int64_t size) {
  Volume v = generate_torus(size);
  for (int64_t k = 0; k < size; ++k)
    for (int64_t j = 0; j < size; ++j)
      for (int64_t i = 0; i < size; ++i) {
        const double x = v.origin[0] + v.spacing[0] * static_cast<double>(i);
        const double y = v.origin[1] + v.spacing[1] * static_cast<double>(j);
        const double z = v.origin[2] + v.spacing[2] * static_cast<double>(k);
        const double disk = std::min(0.1 - std::fabs(z), 0.45 - std::sqrt(x * x + y * y));
        float& f = v.values[v.index(i, j, k)];
        f = std::max(f, static_cast<float>(disk));
      }
  return extract_full_resolution(v, 0.0f);
}

void expect_box(const ComponentStats& c, const Vec& lo, const Vec& hi, double tol) {
  for (int a = 0; a < 3; ++a) {
    EXPECT_NEAR(c.bbox_min[a], lo[a], tol) << "axis " << a;
    EXPECT_NEAR(c.bbox_max[a], hi[a], tol) << "axis " << a;
  }
}

// ---- Measures --------------------------------------------------------------------------------

TEST(MeasureComponents, UnitCubeIsExact) {
  const std::vector<ComponentStats> s = measure_components(unit_cube());
  ASSERT_EQ(s.size(), 1u);
  const ComponentStats& c = s[0];
  EXPECT_EQ(c.triangles, 12);
  EXPECT_EQ(c.vertices, 8);
  EXPECT_EQ(c.edges, 18);
  EXPECT_EQ(c.euler_characteristic, 2);
  EXPECT_TRUE(c.closed);
  EXPECT_EQ(c.genus, 0);
  EXPECT_NEAR(c.area, 6.0, 1e-9);
  ASSERT_TRUE(c.volume);
  EXPECT_NEAR(*c.volume, 1.0, 1e-9);
  EXPECT_TRUE(c.encloses_inside);
  expect_box(c, {0, 0, 0}, {1, 1, 1}, 0);
}

TEST(MeasureComponents, UnitTetrahedronIsExact) {
  const std::vector<ComponentStats> s = measure_components(unit_tetrahedron());
  ASSERT_EQ(s.size(), 1u);
  EXPECT_EQ(s[0].edges, 6);
  EXPECT_EQ(s[0].euler_characteristic, 2);
  EXPECT_EQ(s[0].genus, 0);
  EXPECT_NEAR(s[0].area, 1.5 + std::sqrt(3.0) / 2, 1e-9);
  ASSERT_TRUE(s[0].volume);
  EXPECT_NEAR(*s[0].volume, 1.0 / 6, 1e-9);
  EXPECT_TRUE(s[0].encloses_inside);
}

TEST(MeasureComponents, ReversedOrientationKeepsVolumeButEnclosesOutside) {
  const std::vector<ComponentStats> s = measure_components(flipped(unit_cube()));
  ASSERT_EQ(s.size(), 1u);
  ASSERT_TRUE(s[0].volume);
  EXPECT_NEAR(*s[0].volume, 1.0, 1e-9);
  EXPECT_FALSE(s[0].encloses_inside);
}

TEST(MeasureComponents, VolumeDoesNotDependOnWhereTheComponentSits) {
  const std::vector<ComponentStats> s = measure_components(transformed(unit_cube(), 1.0, {1000, -2000, 3000}));
  ASSERT_EQ(s.size(), 1u);
  EXPECT_NEAR(*s[0].volume, 1.0, 1e-9);
  EXPECT_NEAR(s[0].area, 6.0, 1e-9);
}

TEST(MeasureComponents, OpenSquareHasNoGenusNorVolume) {
  const std::vector<ComponentStats> s = measure_components(open_square());
  ASSERT_EQ(s.size(), 1u);
  EXPECT_EQ(s[0].edges, 5);
  EXPECT_EQ(s[0].boundary_edges, 4);
  EXPECT_EQ(s[0].euler_characteristic, 1);
  EXPECT_FALSE(s[0].closed);
  EXPECT_FALSE(s[0].genus);
  EXPECT_FALSE(s[0].volume);
  EXPECT_FALSE(s[0].encloses_inside);
  EXPECT_NEAR(s[0].area, 1.0, 1e-12);
}

TEST(MeasureComponents, ThreeTrianglesOnOneEdgeAreNotClosed) {
  Mesh m = unit_tetrahedron();
  m.positions.push_back({-1, -1, -1});
  m.triangles.push_back({0, 1, 4});  // a fin on edge 0-1
  const std::vector<ComponentStats> s = measure_components(m);
  ASSERT_EQ(s.size(), 1u);
  EXPECT_EQ(s[0].nonmanifold_edges, 1);
  EXPECT_FALSE(s[0].closed);
  EXPECT_FALSE(s[0].genus);
}

TEST(MeasureComponents, OrdersByTrianglesThenBoxAndLabelsVertices) {
  // Far cube first in the vertex order, then a tetrahedron, then the near cube, then a stray vertex.
  Mesh m = joined(joined(transformed(unit_cube(), 1.0, {5, 0, 0}), transformed(unit_tetrahedron(), 1.0, {-9, 0, 0})),
                  unit_cube());
  m.positions.push_back({0, 0, 0});
  const MeshComponents mc = label_components(m);
  ASSERT_EQ(mc.components.size(), 3u);
  EXPECT_EQ(mc.components[0].bbox_min[0], 0);  // the cubes tie on triangles: lower box first
  EXPECT_EQ(mc.components[1].bbox_min[0], 5);
  EXPECT_EQ(mc.components[2].triangles, 4);
  ASSERT_EQ(mc.vertex_component.size(), 8u + 4u + 8u + 1u);
  for (size_t v = 0; v < 8; ++v) EXPECT_EQ(mc.vertex_component[v], 1);
  for (size_t v = 8; v < 12; ++v) EXPECT_EQ(mc.vertex_component[v], 2);
  for (size_t v = 12; v < 20; ++v) EXPECT_EQ(mc.vertex_component[v], 0);
  EXPECT_EQ(mc.vertex_component[20], -1);
  EXPECT_EQ(measure_components(m), mc.components);
}

TEST(MeasureComponents, EmptyMeshHasNoComponents) {
  const MeshComponents mc = label_components(Mesh{});
  EXPECT_TRUE(mc.components.empty());
  EXPECT_TRUE(mc.vertex_component.empty());
}

TEST(MeasureComponents, RejectsTriangleWithMissingVertex) {
  Mesh m = unit_tetrahedron();
  m.triangles.push_back({0, 1, 4});
  EXPECT_THROW(label_components(m), InvalidInput);
}

TEST(MeasureComponents, SphereMatchesItsRadius) {
  const double r = 0.6;  // generate_sphere's radius
  const std::vector<ComponentStats> s = measure_components(sphere_mesh(65));
  ASSERT_EQ(s.size(), 1u);
  EXPECT_TRUE(s[0].closed);
  EXPECT_EQ(s[0].genus, 0);
  EXPECT_NEAR(s[0].area / (4 * pi * r * r), 1.0, 0.02);
  ASSERT_TRUE(s[0].volume);
  EXPECT_NEAR(*s[0].volume / (4.0 / 3 * pi * r * r * r), 1.0, 0.02);
  EXPECT_TRUE(s[0].encloses_inside);
  expect_box(s[0], {-r, -r, -r}, {r, r, r}, 1e-4);  // the axes' crossings are exact
}

TEST(MeasureComponents, TorusHasGenusOne) {
  const std::vector<ComponentStats> s = measure_components(extract_full_resolution(generate_torus(65), 0.0f));
  ASSERT_EQ(s.size(), 1u);
  EXPECT_TRUE(s[0].closed);
  EXPECT_EQ(s[0].euler_characteristic, 0);
  EXPECT_EQ(s[0].genus, 1);
  EXPECT_TRUE(s[0].encloses_inside);
  // Tube radius 0.2 around a circle of radius 0.5 in z = 0 (generate_torus).
  EXPECT_NEAR(s[0].area / (4 * pi * pi * 0.5 * 0.2), 1.0, 0.03);
  EXPECT_NEAR(*s[0].volume / (2 * pi * pi * 0.5 * 0.2 * 0.2), 1.0, 0.03);
  expect_box(s[0], {-0.7, -0.7, -0.2}, {0.7, 0.7, 0.2}, 0.01);
}

TEST(MeasureComponents, LinkedToriAreTwoGenusOneComponents) {
  const std::vector<ComponentStats> s = measure_components(extract_full_resolution(generate_linked_tori(33), 0.0f));
  ASSERT_EQ(s.size(), 2u);
  for (const ComponentStats& c : s) EXPECT_EQ(c.genus, 1);
}

TEST(MeasureComponents, InnerWallOfHollowShellEnclosesOutside) {
  const std::vector<ComponentStats> s = measure_components(extract_full_resolution(generate_nested_spheres(65), 0.0f));
  ASSERT_EQ(s.size(), 3u);  // largest first: outer wall 0.75, inner wall 0.4, ball 0.2 (generate_nested_spheres)
  const double radius[3] = {0.75, 0.4, 0.2};
  const bool encloses[3] = {true, false, true};
  for (size_t i = 0; i < 3; ++i) {
    SCOPED_TRACE(i);
    EXPECT_EQ(s[i].genus, 0);
    EXPECT_EQ(s[i].encloses_inside, encloses[i]);
    ASSERT_TRUE(s[i].volume);
    EXPECT_NEAR(*s[i].volume / (4.0 / 3 * pi * std::pow(radius[i], 3)), 1.0, 0.04);
    EXPECT_NEAR(s[i].bbox_max[0], radius[i], 0.01);
  }
}

// ---- Comparison ------------------------------------------------------------------------------

std::vector<std::pair<int, int>> diagonal(int n) {
  std::vector<std::pair<int, int>> d;
  for (int i = 0; i < n; ++i) d.push_back({i, i});
  return d;
}

TEST(CompareComponents, MeshAgainstItselfHasNoChanges) {
  const Mesh m = extract_full_resolution(generate_nested_spheres(65), 0.0f);
  const ComponentComparison c = compare_components(m, m, 3 * spacing(65));
  EXPECT_TRUE(c.changes.empty());
  EXPECT_EQ(c.matched_unchanged, diagonal(3));
  EXPECT_GT(c.full_samples, 1000);
  EXPECT_EQ(c.full_samples_matched, c.full_samples);
  EXPECT_EQ(c.adaptive_samples_matched, c.adaptive_samples);
}

TEST(CompareComponents, SubsampledQueriesKeepSmallComponents) {
  // Over 200k samples per side at a one-voxel tolerance, so only a subset looks for neighbours;
  // the small ball (0.2, 4 % of the area) must still be matched, not lost.
  const Mesh m = extract_full_resolution(generate_nested_spheres(129), 0.0f);
  const ComponentComparison c = compare_components(m, m, spacing(129));
  EXPECT_TRUE(c.changes.empty());
  EXPECT_EQ(c.matched_unchanged, diagonal(3));
  EXPECT_LE(c.full_samples, 200000);  // of about 286k samples
  EXPECT_GT(c.full_samples, 100000);
  EXPECT_EQ(c.full_samples_matched, c.full_samples);
}

TEST(CompareComponents, SmallBlobMissingFromAdaptiveIsLost) {
  const Mesh sphere = sphere_mesh(65);
  const Mesh with_blob = joined(sphere, transformed(sphere_mesh(17), 0.25, {0, 0, 1.5}));  // radius 0.15
  const ComponentComparison lost = compare_components(with_blob, sphere, 3 * spacing(65));
  EXPECT_EQ(lost.changes, (std::vector<ComponentChange>{{ChangeKind::lost, {1}, {}, 0, -2}}));
  EXPECT_EQ(lost.matched_unchanged, diagonal(1));
  const ComponentComparison appeared = compare_components(sphere, with_blob, 3 * spacing(65));
  EXPECT_EQ(appeared.changes, (std::vector<ComponentChange>{{ChangeKind::appeared, {}, {1}, 0, 2}}));
  EXPECT_EQ(appeared.matched_unchanged, diagonal(1));
}

TEST(CompareComponents, JoinedBallsAreMergedAndSeparatedOnesSplit) {
  const Mesh apart = beads({false, false}), joined_ab = beads({true, false});
  ASSERT_EQ(measure_components(apart).size(), 3u);
  ASSERT_EQ(measure_components(joined_ab).size(), 2u);
  const ComponentComparison merged = compare_components(apart, joined_ab, 2.0);
  EXPECT_EQ(merged.changes, (std::vector<ComponentChange>{{ChangeKind::merged, {0, 1}, {0}, 0, -2}}));
  EXPECT_EQ(merged.matched_unchanged, (std::vector<std::pair<int, int>>{{2, 1}}));
  const ComponentComparison split = compare_components(joined_ab, apart, 2.0);
  EXPECT_EQ(split.changes, (std::vector<ComponentChange>{{ChangeKind::split, {0}, {0, 1}, 0, 2}}));
  EXPECT_EQ(split.matched_unchanged, (std::vector<std::pair<int, int>>{{1, 2}}));
}

TEST(CompareComponents, MovedJoinIsRearranged) {
  // Full: (A-B) and C; adaptive: A and (B-C).
  const ComponentComparison c = compare_components(beads({true, false}), beads({false, true}), 2.0);
  EXPECT_EQ(c.changes, (std::vector<ComponentChange>{{ChangeKind::rearranged, {0, 1}, {0, 1}, 0, 0}}));
  EXPECT_TRUE(c.matched_unchanged.empty());
}

TEST(CompareComponents, FilledTorusHoleIsAClosedHandle) {
  const Mesh torus = extract_full_resolution(generate_torus(65), 0.0f), filled = filled_torus(65);
  ASSERT_EQ(measure_components(filled).at(0).genus, 0);
  const ComponentComparison closed = compare_components(torus, filled, 3 * spacing(65));
  EXPECT_EQ(closed.changes, (std::vector<ComponentChange>{{ChangeKind::handles_closed, {0}, {0}, -1, 2}}));
  EXPECT_TRUE(closed.matched_unchanged.empty());
  const ComponentComparison opened = compare_components(filled, torus, 3 * spacing(65));
  EXPECT_EQ(opened.changes, (std::vector<ComponentChange>{{ChangeKind::handles_opened, {0}, {0}, 1, -2}}));
}

TEST(CompareComponents, HoleInOpenPatchChangesEuler) {
  const ComponentComparison c = compare_components(grid_patch(false), grid_patch(true), 0.5);
  EXPECT_EQ(c.changes, (std::vector<ComponentChange>{{ChangeKind::euler_changed, {0}, {0}, 0, -1}}));
}

TEST(CompareComponents, CoarseMeshFarFromFullOneRelatesThroughItsTriangles) {
  // Two triangles spanning far beyond the fine patch: their vertices lie more than ten tolerances
  // from it, so only the lattice points of step 1 relate the two.
  const Mesh fine = transformed(grid_patch(false), 1.0 / 3, {0, 0, 0});
  const Mesh coarse = make_mesh({{-3, -3, 0}, {4, -3, 0}, {4, 4, 0}, {-3, 4, 0}}, {{0, 1, 2}, {0, 2, 3}});
  const ComponentComparison c = compare_components(fine, coarse, 0.25);
  EXPECT_TRUE(c.changes.empty());
  EXPECT_EQ(c.matched_unchanged, diagonal(1));
}

TEST(CompareComponents, SmallBallJoinedToLargeOneIsMerged) {
  // The small ball is under 10% of the joined surface: only its own side relates the two.
  const std::vector<Ball> balls = {{14, 10.3}, {30, 2.3}};  // surfaces 3.4 voxels apart
  const Mesh apart = balls_and_bars(balls, {}), joined_ab = balls_and_bars(balls, {{14, 30, 1.5}});
  const ComponentComparison c = compare_components(apart, joined_ab, 2.0);
  EXPECT_EQ(c.changes, (std::vector<ComponentChange>{{ChangeKind::merged, {0, 1}, {0}, 0, -2}}));
}

Mesh adaptive_mesh(const Volume& v, double eps, TopologyMode mode) {
  ExtractOptions o;
  o.eps = eps;
  o.topology = mode;
  return extract(MultiresVolume::build(v), o);
}

TEST(CompareComponents, TopologyPreservingExtractionHasNoChanges) {
  const Volume v = generate_linked_tori(65);
  const Mesh full = extract_full_resolution(v, 0.0f), adaptive = adaptive_mesh(v, 1.0, TopologyMode::preserve);
  ASSERT_LT(adaptive.triangles.size(), full.triangles.size() / 4);
  const ComponentComparison c = compare_components(full, adaptive, 3 * spacing(65));
  EXPECT_TRUE(c.changes.empty());
  EXPECT_EQ(c.matched_unchanged, diagonal(2));
}

TEST(CompareComponents, CoarseTorusWithoutTopologyControlSplits) {
  const Volume v = generate_torus(65);
  const Mesh full = extract_full_resolution(v, 0.0f), adaptive = adaptive_mesh(v, 1.0, TopologyMode::none);
  const auto pieces = static_cast<int>(measure_components(adaptive).size());
  ASSERT_GT(pieces, 1);
  std::vector<int> all(static_cast<size_t>(pieces));
  std::iota(all.begin(), all.end(), 0);
  const ComponentComparison c = compare_components(full, adaptive, 3 * spacing(65));
  ASSERT_EQ(c.changes.size(), 1u);
  EXPECT_EQ(c.changes[0].kind, ChangeKind::split);
  EXPECT_EQ(c.changes[0].full, std::vector<int>{0});
  EXPECT_EQ(c.changes[0].adaptive, all);
  EXPECT_EQ(c.changes[0].genus_change, -1);  // the pieces are balls
}

// Three beads, the bar moved from the first pair to the second: two components on each side,
// related many to many, which compare_components reads as rearranged. The same
// result again, and through the overload the report uses (labels computed once).
TEST(CompareComponents, AJoinMovedToTheNextPairReadsAsRearrangedTheSameEveryTime) {
  const Mesh a = beads({true, false}), b = beads({false, true});
  const MeshComponents la = label_components(a), lb = label_components(b);
  ASSERT_EQ(la.components.size(), 2u);
  ASSERT_EQ(lb.components.size(), 2u);
  const ComponentComparison first = compare_components(a, b, 2.0);
  ASSERT_EQ(first.changes.size(), 1u);
  EXPECT_EQ(first.changes[0].kind, ChangeKind::rearranged);
  EXPECT_EQ(first.changes[0].full, (std::vector<int>{0, 1}));
  EXPECT_EQ(first.changes[0].adaptive, (std::vector<int>{0, 1}));
  EXPECT_TRUE(first.matched_unchanged.empty());
  EXPECT_TRUE(compare_components(a, b, 2.0) == first);
  EXPECT_TRUE(compare_components(a, la, b, lb, 2.0) == first);
}

TEST(CompareComponents, EmptyMeshesCompareEqual) {
  const ComponentComparison c = compare_components(Mesh{}, Mesh{}, 1.0);
  EXPECT_TRUE(c.changes.empty());
  EXPECT_TRUE(c.matched_unchanged.empty());
  const ComponentComparison lost = compare_components(unit_cube(), Mesh{}, 1.0);
  EXPECT_EQ(lost.changes, (std::vector<ComponentChange>{{ChangeKind::lost, {0}, {}, 0, -2}}));
}

TEST(CompareComponents, RejectsBadTolerance) {
  const Mesh m = unit_cube();
  EXPECT_THROW(compare_components(m, m, 0.0), InvalidInput);
  EXPECT_THROW(compare_components(m, m, -1.0), InvalidInput);
  EXPECT_THROW(compare_components(m, m, std::nan("")), InvalidInput);
  EXPECT_THROW(compare_components(m, m, 1e-12), InvalidInput);
}

TEST(CompareComponents, KindsHaveNames) {
  EXPECT_EQ(to_string(ChangeKind::handles_closed), "handles_closed");
  EXPECT_EQ(to_string(ChangeKind::lost), "lost");
}

}  // namespace
}  // namespace isotope
