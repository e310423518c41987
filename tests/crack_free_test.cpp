// Invariant 3 of docs/DESIGN.md: no cracks at any eps in any mode: closed surfaces stay closed and
// manifold, open ones end only on the faces of the data box, and nothing lies outside it.
#include <gtest/gtest.h>

#include <algorithm>
#include <map>

#include "engine/core/fields.h"
#include "engine/extract/extract.h"
#include "engine/hierarchy/multires_volume.h"
#include "tests/test_support.h"

namespace isotope {
namespace {

// Every directed edge of a closed, consistently oriented surface appears once, and so does
// its reverse.
int64_t orientation_defects(const Mesh& m) {
  std::map<std::pair<uint32_t, uint32_t>, int> directed;
  for (const auto& t : m.triangles)
    for (int i = 0; i < 3; ++i) ++directed[{t[i], t[(i + 1) % 3]}];
  int64_t bad = 0;
  for (const auto& [e, n] : directed) {
    const auto it = directed.find({e.second, e.first});
    if (n != 1 || it == directed.end() || it->second != 1) ++bad;
  }
  return bad;
}

struct Shape {
  const char* name;
  Volume volume;
  int64_t components, euler;
};

TEST(CrackFree, ClosedShapesStayClosedManifoldAndOrientedAtEveryEps) {
  const Shape shapes[] = {
      {"sphere 33", generate_sphere(33), 1, 2},
      {"torus 41", generate_torus(41), 1, 0},
      {"linked tori 33", generate_linked_tori(33), 2, 0},
      {"nested spheres 45", generate_nested_spheres(45), 3, 6},
  };
  for (const Shape& s : shapes) {
    const MultiresVolume mv = MultiresVolume::build(s.volume);
    for (double eps : {0.0, 0.005, 0.02, 0.1, 0.5, 5.0})
      for (ErrorIndicator err : {ErrorIndicator::bound, ErrorIndicator::surplus})
        for (TopologyMode mode : {TopologyMode::none, TopologyMode::paper, TopologyMode::preserve}) {
          ExtractOptions o;
          o.eps = eps;
          o.error = err;
          o.topology = mode;
          const Mesh m = extract(mv, o);
          const MeshTopology t = measure_topology(m);
          const std::string what = std::string(s.name) + " eps " + std::to_string(eps) + " " +
                                   std::string(to_string(err)) + " " + std::string(to_string(mode));
          EXPECT_EQ(t.boundary_edges, 0) << what;
          EXPECT_EQ(t.nonmanifold_edges, 0) << what;
          EXPECT_EQ(orientation_defects(m), 0) << what;
          if (eps == 0.0 || mode == TopologyMode::preserve) {
            EXPECT_EQ(t.components, s.components) << what;
            EXPECT_EQ(t.euler_characteristic, s.euler) << what;
          }
        }
  }
}

// A triangle budget's steps within one key (tie classes, docs/METHOD.md): every refined diamond's
// parents are refined there too, so the meshes stay closed, and with preserve keep their topology.
TEST(CrackFree, TieClassStepsOfATriangleBudgetStayClosed) {
  const Shape shapes[] = {
      {"sphere 33", generate_sphere(33), 1, 2},
      {"torus 41", generate_torus(41), 1, 0},
      {"nested spheres 45", generate_nested_spheres(45), 3, 6},
  };
  int with_ties = 0;
  for (const Shape& s : shapes) {
    const MultiresVolume mv = MultiresVolume::build(s.volume);
    const auto full = static_cast<int64_t>(extract(mv, ExtractOptions{}).triangles.size());
    for (TopologyMode mode : {TopologyMode::none, TopologyMode::preserve})
      for (int64_t percent : {3, 7, 12, 20, 30, 45, 60, 80}) {
        ExtractOptions o;
        o.topology = mode;
        o.max_triangles = full * percent / 100;
        ExtractStats stats;
        Mesh m;
        const std::string what =
            std::string(s.name) + " " + std::string(to_string(mode)) + " budget " + std::to_string(o.max_triangles);
        try {
          m = extract(mv, o, &stats);
        } catch (const TriangleBudgetTooSmall&) {
          continue;
        }
        with_ties += stats.chosen_eps_ties >= 0;
        const MeshTopology t = measure_topology(m);
        EXPECT_LE(t.triangles, o.max_triangles) << what;
        EXPECT_EQ(t.boundary_edges, 0) << what << ", eps-ties " << stats.chosen_eps_ties;
        EXPECT_EQ(t.nonmanifold_edges, 0) << what << ", eps-ties " << stats.chosen_eps_ties;
        EXPECT_EQ(orientation_defects(m), 0) << what << ", eps-ties " << stats.chosen_eps_ties;
        if (mode == TopologyMode::preserve) {
          EXPECT_EQ(t.components, s.components) << what;
          EXPECT_EQ(t.euler_characteristic, s.euler) << what;
        }
      }
  }
  // uint8 volumes: integer values make many errors 0 along an edge, so a diamond often has its
  // child's key exactly, and the parent must be among the classes refined before the child.
  for (const auto& s : testing::shared_volumes()) {
    const Volume v = testing::load_shared(s);
    const MultiresVolume mv = MultiresVolume::build(v);
    for (float iso : s.isovalues) {
      ExtractOptions base;
      base.iso = iso;
      base.topology = TopologyMode::none;
      const auto full = static_cast<int64_t>(extract(mv, base).triangles.size());
      for (int64_t percent : {5, 10, 20, 40, 70}) {
        ExtractOptions o = base;
        o.max_triangles = std::max<int64_t>(1, full * percent / 100);
        ExtractStats stats;
        Mesh m;
        const std::string what = s.name + " iso " + std::to_string(iso) + " budget " + std::to_string(o.max_triangles);
        try {
          m = extract(mv, o, &stats);
        } catch (const TriangleBudgetTooSmall&) {
          continue;
        }
        with_ties += stats.chosen_eps_ties >= 0;
        EXPECT_EQ(measure_topology(m).nonmanifold_edges, 0) << what << ", eps-ties " << stats.chosen_eps_ties;
        EXPECT_EQ(testing::interior_boundary_edges(m, v), 0) << what << ", eps-ties " << stats.chosen_eps_ties;
      }
    }
  }
  EXPECT_GT(with_ties, 30);
}

void expect_crack_free(const Volume& v, float iso, const std::string& name) {
  const MultiresVolume mv = MultiresVolume::build(v);
  float lo = *std::min_element(v.values.begin(), v.values.end());
  float hi = *std::max_element(v.values.begin(), v.values.end());
  for (double rel : {0.0, 0.01, 0.05, 0.2, 1.0})
    for (TopologyMode mode : {TopologyMode::none, TopologyMode::paper, TopologyMode::preserve}) {
      ExtractOptions o;
      o.iso = iso;
      o.eps = rel * (hi - lo);
      o.topology = mode;
      const Mesh m = extract(mv, o);
      const std::string what =
          name + " iso " + std::to_string(iso) + " eps " + std::to_string(o.eps) + " " + std::string(to_string(mode));
      EXPECT_GT(m.triangles.size(), 0u) << what;
      EXPECT_EQ(measure_topology(m).nonmanifold_edges, 0) << what;
      EXPECT_EQ(testing::interior_boundary_edges(m, v), 0) << what;
      EXPECT_EQ(testing::vertices_outside_box(m, v), 0) << what;
    }
}

TEST(CrackFree, RealVolumesEndOnlyOnTheDataBoxAndNeverLeaveIt) {
  for (const auto& s : testing::shared_volumes()) {
    const Volume v = testing::load_shared(s);
    for (float iso : s.isovalues) expect_crack_free(v, iso, s.name);
  }
}

TEST(CrackFree, IntegerIsovaluesOnUint8DataTieConsistently) {
  // Values equal to the isovalue are everywhere here; one rule (inside iff value > iso) holds.
  for (const auto& s : testing::shared_volumes()) {
    if (s.name == "hydrogen") continue;
    const Volume v = testing::load_shared(s);
    for (float iso : {32.0f, 128.0f, 229.0f, 253.0f}) expect_crack_free(v, iso, s.name + " tie");
  }
}

}  // namespace
}  // namespace isotope
