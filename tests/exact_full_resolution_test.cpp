// Invariant 2 of design.md: at eps = 0 the adaptive extraction is exactly marching tetrahedra
// over every finest tetrahedron (same triangles), whatever the mode, indicator or dimensions.
#include <gtest/gtest.h>

#include "engine/extract.h"
#include "engine/fields.h"
#include "engine/multires_volume.h"
#include "tests/test_support.h"

namespace isotope {
namespace {

using testing::triangle_set;

void expect_exact_at_eps0(const Volume& volume, float iso, const std::string& what) {
  const auto full = triangle_set(extract_full_resolution(volume, iso));
  const MultiresVolume mv = MultiresVolume::build(volume);
  for (ErrorIndicator err : {ErrorIndicator::bound, ErrorIndicator::surplus})
    for (TopologyMode mode : {TopologyMode::none, TopologyMode::paper, TopologyMode::preserve}) {
      ExtractOptions o;
      o.iso = iso;
      o.error = err;
      o.topology = mode;
      const auto adaptive = triangle_set(extract(mv, o));
      ASSERT_EQ(adaptive.size(), full.size()) << what << " iso " << iso << " " << to_string(err) << " " << to_string(mode);
      EXPECT_TRUE(adaptive == full) << what << " iso " << iso;
    }
}

TEST(ExactAtEpsZero, AlgebraicFunctionGivesThePinnedTriangleCount) {
  const Volume v = generate_algebraic(65);
  EXPECT_EQ(extract_full_resolution(v, 0.0f).triangles.size(), 58772u) << "inside means value > iso";
  expect_exact_at_eps0(v, 0.0f, "algebraic 65");
  expect_exact_at_eps0(generate_algebraic(65, {0.15625, 0.09375, 0}), 0.0f, "algebraic 65 shifted");
}

TEST(ExactAtEpsZero, SyntheticFieldsOfAnyDimensions) {
  expect_exact_at_eps0(generate_sphere(33), 0.0f, "sphere 33");
  expect_exact_at_eps0(generate_torus(40), 0.0f, "torus 40");
  expect_exact_at_eps0(generate_linked_tori(37), 0.0f, "linked tori 37");
  const Volume noise = testing::crop(generate_noise(30, 7), {30, 19, 23});
  for (float iso : {-0.4f, 0.0f, 0.25f}) expect_exact_at_eps0(noise, iso, "noise 30x19x23");
  expect_exact_at_eps0(testing::crop(generate_noise(9, 3), {2, 9, 5}), 0.0f, "noise 2x9x5");
}

TEST(ExactAtEpsZero, RealVolumesAtTheirIsovaluesAndAtIntegerTies) {
  for (const auto& s : testing::shared_volumes()) {
    const Volume v = testing::load_shared(s);
    for (float iso : s.isovalues) expect_exact_at_eps0(v, iso, s.name);
    if (s.name != "hydrogen") expect_exact_at_eps0(v, 128.0f, s.name + " integer iso");
  }
}

TEST(ExactAtEpsZero, MeshIsWeldedOneVertexPerCutGridEdge) {
  const Mesh m = extract_full_resolution(generate_sphere(33), 0.0f);
  const MeshTopology t = measure_topology(m);
  EXPECT_EQ(t.vertices, static_cast<int64_t>(m.positions.size()));
  EXPECT_EQ(t.euler_characteristic, 2);
  EXPECT_EQ(t.components, 1);
}

}  // namespace
}  // namespace isotope
