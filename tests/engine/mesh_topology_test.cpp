// isotope::measure_topology, what every topology claim is checked with: counts on
// small meshes worked out by hand, and the same counts on any number of threads, also as the
// component report's totals.
#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <algorithm>
#include <numeric>
#include <string>
#include <tuple>

#include "engine/diagnostics/component_report.h"
#include "engine/extract/extract_drivers.h"
#include "engine/synthetic/fields.h"
#include "engine/topology/filed_edges.h"
#include "isotope/mesh.h"

namespace isotope {
namespace {

Mesh mesh_of(size_t vertices, std::vector<std::array<uint32_t, 3>> triangles) {
  Mesh m;
  m.positions.resize(vertices, {0, 0, 0});  // resize() alone leaves them unwritten
  for (const auto& t : triangles) m.triangles.push_back(t);
  return m;
}

TEST(MeshTopology, OneTriangleHasThreeBoundaryEdges) {
  const MeshTopology t = measure_topology(mesh_of(3, {{0, 1, 2}}));
  EXPECT_EQ(t.vertices, 3);
  EXPECT_EQ(t.edges, 3);
  EXPECT_EQ(t.boundary_edges, 3);
  EXPECT_EQ(t.nonmanifold_edges, 0);
  EXPECT_EQ(t.components, 1);
  EXPECT_EQ(t.euler_characteristic, 1);
}

TEST(MeshTopology, TetrahedronSurfaceIsClosedWithEulerTwo) {
  const MeshTopology t = measure_topology(mesh_of(4, {{0, 2, 1}, {0, 1, 3}, {1, 2, 3}, {0, 3, 2}}));
  EXPECT_EQ(t.edges, 6);
  EXPECT_EQ(t.boundary_edges, 0);
  EXPECT_EQ(t.nonmanifold_edges, 0);
  EXPECT_EQ(t.euler_characteristic, 2);
}

TEST(MeshTopology, ThreeTrianglesOnOneEdgeMakeItNonManifold) {
  const MeshTopology t = measure_topology(mesh_of(5, {{0, 1, 2}, {1, 0, 3}, {0, 1, 4}}));
  EXPECT_EQ(t.edges, 7);
  EXPECT_EQ(t.nonmanifold_edges, 1);
  EXPECT_EQ(t.boundary_edges, 6);
  EXPECT_EQ(t.components, 1);
}

TEST(MeshTopology, UnusedVerticesAreNotCountedAndDisjointPiecesAreComponents) {
  // Vertices 0 and 8 belong to no triangle; two triangles sharing an edge, and a separate third.
  const MeshTopology t = measure_topology(mesh_of(9, {{1, 2, 3}, {3, 2, 4}, {5, 6, 7}}));
  EXPECT_EQ(t.vertices, 7);
  EXPECT_EQ(t.components, 2);
  EXPECT_EQ(t.edges, 8);
  EXPECT_EQ(t.boundary_edges, 7);
  EXPECT_EQ(t.euler_characteristic, 7 - 8 + 3);
}

TEST(MeshTopology, AnyThreadCountGivesTheSameCounts) {
  // Two linked tori at full resolution: over a hundred thousand triangles, many tasks, and on more
  // than one thread the vertices split into parts, each counted by its own thread.
  ExtractOptions o;
  const Mesh m = extract(generate_linked_tori(129), o);
  ASSERT_GT(m.triangles.size(), 100000u);
  const MeshTopology one = [&] {
    const tbb::global_control limit(tbb::global_control::max_allowed_parallelism, 1);
    return measure_topology(m);
  }();
  EXPECT_EQ(one.components, 2);
  EXPECT_EQ(one.euler_characteristic, 0);
  EXPECT_EQ(one.boundary_edges, 0);
  EXPECT_EQ(one.nonmanifold_edges, 0);
  EXPECT_EQ(one.edges * 2, one.triangles * 3) << "closed: every edge has two triangles";
  // The same mesh with holes and fins: every 10th triangle dropped (boundary edges), every 13th
  // given twice (two to four triangles on its edges), so that every count means something.
  Mesh torn;
  torn.positions = m.positions;
  for (size_t i = 0; i < m.triangles.size(); ++i) {
    if (i % 10 == 0) continue;
    torn.triangles.push_back(m.triangles[i]);
    if (i % 13 == 0) torn.triangles.push_back(m.triangles[i]);
  }
  const MeshTopology torn_one = [&] {
    const tbb::global_control limit(tbb::global_control::max_allowed_parallelism, 1);
    return measure_topology(torn);
  }();
  EXPECT_GT(torn_one.boundary_edges, 0);
  EXPECT_GT(torn_one.nonmanifold_edges, 0);
  auto expect_same = [](const MeshTopology& got, const MeshTopology& want, size_t threads) {
    EXPECT_EQ(got.vertices, want.vertices) << threads << " threads";
    EXPECT_EQ(got.triangles, want.triangles) << threads << " threads";
    EXPECT_EQ(got.edges, want.edges) << threads << " threads";
    EXPECT_EQ(got.components, want.components) << threads << " threads";
    EXPECT_EQ(got.euler_characteristic, want.euler_characteristic) << threads << " threads";
    EXPECT_EQ(got.boundary_edges, want.boundary_edges) << threads << " threads";
    EXPECT_EQ(got.nonmanifold_edges, want.nonmanifold_edges) << threads << " threads";
  };
  // The component report finds the edges the same way: its components' totals are the same
  // counts, and its labels the same on any number of threads.
  const MeshComponents torn_components = [&] {
    const tbb::global_control limit(tbb::global_control::max_allowed_parallelism, 1);
    return label_components(torn);
  }();
  expect_same(total_topology(torn_components.components), torn_one, 1);
  // The same triangles in a scattered order: each run of triangles then uses vertices from all over
  // the mesh, and every part reads every run (in the engine's order, a part reads only the runs
  // whose vertices meet its own).
  const size_t count = torn.triangles.size();
  ASSERT_EQ(std::gcd(size_t{7919}, count), 1u) << "a permutation needs 7919 prime to the count";
  Mesh scattered;
  scattered.positions = torn.positions;
  for (size_t i = 0; i < count; ++i) scattered.triangles.push_back(torn.triangles[(i * 7919) % count]);
  // The filed edges on one thread, each vertex's entries sorted: the same for any triangle order,
  // any thread count, and with 64-bit offsets (which a mesh of 1.4 G triangles or more takes).
  const FiledEdges<uint32_t> filed = [&] {
    const tbb::global_control limit(tbb::global_control::max_allowed_parallelism, 1);
    return file_edges<uint32_t>(torn);
  }();
  EXPECT_EQ(filed.edges, torn_one.edges);
  const auto expect_filed = [&](const auto& got, const std::string& what) {
    EXPECT_TRUE(std::equal(got.first.begin(), got.first.end(), filed.first.begin(), filed.first.end())) << what;
    EXPECT_TRUE(got.upper == filed.upper && got.used == filed.used && got.root == filed.root) << what;
    EXPECT_EQ(std::tie(got.edges, got.boundary_edges, got.nonmanifold_edges),
              std::tie(filed.edges, filed.boundary_edges, filed.nonmanifold_edges))
        << what;
  };
  for (size_t threads : {1, 2, 3, 5}) {
    const tbb::global_control limit(tbb::global_control::max_allowed_parallelism, threads);
    const std::string on = " on " + std::to_string(threads) + " threads";
    expect_filed(file_edges<uint32_t>(torn), "torn" + on);
    expect_filed(file_edges<uint64_t>(torn), "torn, 64-bit offsets" + on);
    expect_filed(file_edges<uint32_t>(scattered), "scattered" + on);
    if (threads == 1) continue;
    expect_same(measure_topology(m), one, threads);
    expect_same(measure_topology(torn), torn_one, threads);
    expect_same(measure_topology(scattered), torn_one, threads);
    EXPECT_TRUE(label_components(torn) == torn_components) << threads << " threads";
  }
}

}  // namespace
}  // namespace isotope
