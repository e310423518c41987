// isotope::vertex_normals, the shading normals GLB, VTP and the viewer carry: area-weighted
// sums of the triangles' normals, the same bits on any number of threads as one walk over the
// triangles in order.
#include "engine/mesh/vertex_normals.h"

#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <atomic>
#include <cmath>
#include <limits>
#include <span>
#include <vector>

#include "engine/extract/extract_drivers.h"
#include "engine/mesh/vertex_parts.h"
#include "engine/synthetic/fields.h"
#include "isotope/mesh.h"

namespace isotope {
namespace {

// One walk over the triangles in order, summing in double: what every thread count must give.
std::vector<std::array<float, 3>> one_walk(const Mesh& mesh) {
  std::vector<std::array<double, 3>> sum(mesh.positions.size(), {0, 0, 0});
  for (const auto& t : mesh.triangles) {
    const auto &a = mesh.positions[t[0]], &b = mesh.positions[t[1]], &c = mesh.positions[t[2]];
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

TEST(VertexNormals, AnyThreadCountGivesOneWalksBitsAndUnitLength) {
  // Two linked tori at full resolution: over a hundred thousand triangles, their vertices split
  // into ranges that many triangles straddle.
  ExtractOptions o;
  const Mesh m = extract(generate_linked_tori(129), o);
  ASSERT_GT(m.positions.size(), 50000u);
  const std::vector<std::array<float, 3>> expected = one_walk(m);
  for (size_t threads : {1, 2, 3, 7}) {
    const tbb::global_control limit(tbb::global_control::max_allowed_parallelism, threads);
    const std::vector<std::array<float, 3>> normals = vertex_normals(m);
    ASSERT_EQ(normals.size(), expected.size());
    size_t differ = 0;
    for (size_t i = 0; i < normals.size(); ++i) differ += normals[i] != expected[i];
    EXPECT_EQ(differ, 0u) << threads << " threads";
  }
  for (const auto& n : expected) EXPECT_NEAR(std::hypot(n[0], n[1], n[2]), 1.0, 1e-5);

  // The same triangles in a scattered order: every chunk of them spans the vertices, so the parts
  // read chunks that other parts read too, and each must still sum in triangle order.
  Mesh scattered = m;
  const size_t count = m.triangles.size();
  for (size_t i = 0; i < count; ++i) scattered.triangles[i] = m.triangles[i * 7919 % count];
  ASSERT_NE(count % 7919, 0u);
  const std::vector<std::array<float, 3>> expected_scattered = one_walk(scattered);
  for (size_t threads : {1, 2, 3, 7}) {
    const tbb::global_control limit(tbb::global_control::max_allowed_parallelism, threads);
    const std::vector<std::array<float, 3>> normals = vertex_normals(scattered);
    size_t differ = 0;
    for (size_t i = 0; i < normals.size(); ++i) differ += normals[i] != expected_scattered[i];
    EXPECT_EQ(differ, 0u) << threads << " threads, scattered";
  }
}

TEST(VertexNormals, AVertexOfNoTriangleGetsZero) {
  Mesh m;
  m.positions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {5, 5, 5}};
  m.triangles = {{0, 1, 2}};
  const auto n = vertex_normals(m);
  EXPECT_EQ(n[0], (std::array<float, 3>{0, 0, 1}));
  EXPECT_EQ(n[3], (std::array<float, 3>{0, 0, 0}));
}

// Into an array the writers do not zero-fill: every vertex is written on any thread count, a
// vertex without a normal (of a degenerate triangle only, or of none) with the one asked for.
TEST(VertexNormals, IntoAnArrayEveryVertexIsWrittenThoseWithoutANormalAsAsked) {
  ExtractOptions o;
  Mesh m = extract(generate_linked_tori(129), o);
  ASSERT_GT(chunks_of(m.triangles.size()), 2) << "parts that read chunks of other parts";
  const auto first = static_cast<uint32_t>(m.positions.size());
  m.positions.push_back({1, 1, 1});
  m.positions.push_back({2, 2, 2});
  m.positions.push_back({3, 3, 3});  // on one line: a triangle of no area
  m.positions.push_back({9, 9, 9});  // in no triangle
  m.triangles.push_back({first, first + 1, first + 2});
  const std::vector<std::array<float, 3>> expected = one_walk(m);
  const std::array<float, 3> none = {0, 0, 1};
  for (size_t threads : {1, 2, 7}) {
    const tbb::global_control limit(tbb::global_control::max_allowed_parallelism, threads);
    const float nan = std::numeric_limits<float>::quiet_NaN();
    std::vector<std::array<float, 3>> out(m.positions.size(), {nan, nan, nan});
    vertex_normals_into(m, out, none);
    size_t differ = 0;
    for (size_t i = 0; i < out.size(); ++i) {
      const bool has = expected[i] != std::array<float, 3>{0, 0, 0};
      differ += out[i] != (has ? expected[i] : none);
    }
    EXPECT_EQ(differ, 0u) << threads << " threads";
    for (uint32_t i = first; i < first + 4; ++i) EXPECT_EQ(out[i], none) << i;
  }
  std::vector<std::array<float, 3>> short_by_one(m.positions.size() - 1);
  EXPECT_THROW(vertex_normals_into(m, short_by_one, none), InvalidInput);
}

// Run by run, as the writers take them: every vertex in exactly one run, no run longer than
// kNormalsPerRun, and each the normals vertex_normals_into gives, on any thread count (on one
// thread the whole mesh is one part, cut into runs).
TEST(VertexNormals, RunByRunEveryVertexComesOnceWithTheSameNormal) {
  ExtractOptions o;
  Mesh m = extract(generate_linked_tori(193), o);
  ASSERT_GT(m.positions.size(), 2 * kNormalsPerRun) << "parts of several runs";
  m.positions.push_back({9, 9, 9});  // in no triangle
  const std::array<float, 3> none = {0, 0, 1};
  std::vector<std::array<float, 3>> expected(m.positions.size());
  vertex_normals_into(m, expected, none);
  for (size_t threads : {1, 2, 7}) {
    const tbb::global_control limit(tbb::global_control::max_allowed_parallelism, threads);
    std::vector<std::array<float, 3>> got(m.positions.size(), {0, 0, 0});
    std::vector<std::atomic<int>> seen(m.positions.size());
    std::atomic<size_t> too_long{0}, runs{0};
    for_each_vertex_normals_run(m, none, [&](uint32_t first, std::span<const std::array<float, 3>> normals) {
      ++runs;
      if (normals.size() > kNormalsPerRun) ++too_long;
      for (size_t k = 0; k < normals.size(); ++k) {
        ++seen[first + k];
        got[first + k] = normals[k];
      }
    });
    size_t not_once = 0;
    for (const auto& s : seen) not_once += s.load() != 1;
    EXPECT_EQ(not_once, 0u) << threads << " threads";
    EXPECT_EQ(too_long.load(), 0u) << threads << " threads";
    EXPECT_GT(runs.load(), 2u) << threads << " threads";
    EXPECT_TRUE(got == expected) << threads << " threads";
  }
}

}  // namespace
}  // namespace isotope
