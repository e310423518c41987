// Compact records (docs/FORMAT.md, "Compact records"): every code rounds its field the conservative way, the
// rounding commutes with saturation, and the meshes of the compact hierarchy differ from those of
// the exact records only by refining more: none with the bound is the same mesh, every other mode
// within 5% of the triangles and with the same topology where preserve keeps it.
#include "engine/hierarchy/compact_record.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <limits>
#include <random>

#include "engine/extract/extract_drivers.h"
#include "engine/hierarchy/hierarchy.h"
#include "engine/hierarchy/multires_volume.h"
#include "engine/synthetic/fields.h"
#include "isotope/mesh.h"
#include "tests/support/test_support.h"

namespace isotope {
namespace {

TEST(CompactRecord, RoundingIsConservativeMonotoneAndExactOnCodes) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> any(-1e6f, 1e6f);
  for (int i = 0; i < 200000; ++i) {
    const float f = i % 3 == 0 ? any(rng) : std::ldexp(any(rng), static_cast<int>(rng() % 80) - 60);
    const float up = bf16_to_float(bf16_up(f)), down = bf16_to_float(bf16_down(f));
    ASSERT_GE(up, f) << f;
    ASSERT_LE(down, f) << f;
    ASSERT_LE(up - down, std::fabs(f) / 128 + 1e-38f) << f << ": more than 2^-7 apart";
    EXPECT_EQ(bf16_up(up), bf16_up(f)) << "a code rounds to itself";
    const float g = any(rng);
    if (f <= g) {
      ASSERT_LE(up, bf16_to_float(bf16_up(g))) << "monotone";
      ASSERT_LE(down, bf16_to_float(bf16_down(g))) << "monotone";
    }
  }
  const float inf = std::numeric_limits<float>::infinity();
  EXPECT_EQ(bf16_to_float(bf16_up(inf)), inf);
  EXPECT_EQ(bf16_to_float(bf16_up(std::numeric_limits<float>::max())), inf) << "beyond the largest code: infinity";
  EXPECT_EQ(bf16_to_float(bf16_up(0.0f)), 0.0f);
  EXPECT_EQ(bf16_to_float(bf16_down(0.0f)), 0.0f);
  for (float exact : {1.0f, 0.5f, 255.0f, -3.0f, 0.0f}) {  // codes of their own
    EXPECT_EQ(bf16_to_float(bf16_up(exact)), exact);
    EXPECT_EQ(bf16_to_float(bf16_down(exact)), exact);
  }
}

TEST(CompactRecord, RecordsRoundOutwardAndKeepTheBound) {
  Record r;
  r.bounds = {0.1f, 0.7f, 0.123456f, 0.0987f};
  r.topology.exact_lo = 0.3f, r.topology.exact_hi = 0.31f;
  r.topology.weight = {0.01f, 3.3f, 17.0f};
  const Record c = round_record(r);
  EXPECT_LE(c.bounds.lo, r.bounds.lo);
  EXPECT_GE(c.bounds.hi, r.bounds.hi);
  EXPECT_EQ(std::bit_cast<uint32_t>(c.bounds.error_bound), std::bit_cast<uint32_t>(r.bounds.error_bound))
      << "the L-infinity bound is kept as it is";
  EXPECT_GE(c.bounds.error_surplus, r.bounds.error_surplus);
  EXPECT_LE(c.topology.exact_lo, r.topology.exact_lo);
  EXPECT_GE(c.topology.exact_hi, r.topology.exact_hi);
  EXPECT_GE(c.topology.paper_lo, c.topology.paper_hi) << "an empty interval stays empty";
  for (size_t w = 0; w < 3; ++w) EXPECT_GE(c.topology.weight[w], r.topology.weight[w]);
}

// A record without an interval holds (+infinity, -infinity), which the store writes as {1, 0}:
// the words stores held before, so that stores keep their bytes; other empty intervals as they are.
TEST(CompactRecord, NoIntervalIsStoredAsOneZero) {
  const Record none;
  const PackedTopology p = pack_topology(none.topology, 0.0f);
  EXPECT_EQ(p.exact_lo, bf16_down(1.0f));
  EXPECT_EQ(p.exact_hi, bf16_up(0.0f));
  EXPECT_EQ(p.paper_lo, bf16_down(1.0f));
  EXPECT_EQ(p.paper_hi, bf16_up(0.0f));
  EXPECT_NE(bf16_down(1.0f), bf16_down(0.0f));
  DiamondTopology absent{0, 0, 2, 2, {0, 0, 0}};
  const PackedTopology q = pack_topology(absent, 0.0f);
  EXPECT_EQ(q.exact_lo, bf16_down(0.0f));
  EXPECT_EQ(q.exact_hi, bf16_up(0.0f));
  EXPECT_EQ(q.paper_lo, bf16_down(2.0f));
  EXPECT_EQ(q.paper_hi, bf16_up(2.0f));
  const DiamondTopology back = unpack(p);
  EXPECT_FALSE(back.exact_lo < back.exact_hi);
  EXPECT_FALSE(back.paper_lo < back.paper_hi);
}

// The meshes of the compact hierarchy against those of the exact records, on the shared volumes
// and synthetic fields, over modes and eps.
TEST(CompactRecord, MeshesRefineOnlyMoreAndStayWithinFivePercent) {
  struct Case {
    std::string name;
    Volume volume;
    float iso;
  };
  std::vector<Case> cases = {{"noise", testing::crop(generate_noise(40, 11), {40, 35, 29}), 0.1f},
                             {"linked tori", generate_linked_tori(41), 0.0f}};
  for (const auto& s : testing::shared_volumes()) cases.push_back({s.name, testing::load_shared(s), s.isovalues[1]});
  int compared = 0, differing = 0;
  for (const Case& c : cases) {
    const MultiresVolume exact = MultiresVolume::build(c.volume);
    const Hierarchy compact = Hierarchy::build(c.volume);
    const auto [lo, hi] = std::minmax_element(c.volume.values.begin(), c.volume.values.end());
    for (double rel : {0.002, 0.01, 0.05, 0.2})
      for (TopologyMode mode :
           {TopologyMode::none, TopologyMode::paper, TopologyMode::preserve, TopologyMode::simplify})
        for (ErrorIndicator error : {ErrorIndicator::bound, ErrorIndicator::surplus}) {
          ExtractOptions o;
          o.iso = c.iso, o.eps = rel * (*hi - *lo), o.topology = mode, o.error = error;
          if (mode == TopologyMode::simplify) o.delta = 0.02 * (*hi - *lo);
          const Mesh a = extract(exact, o), b = extract(compact, o);
          const std::string what = c.name + " eps " + std::to_string(o.eps) + " " + std::string(to_string(mode)) + " " +
                                   std::string(to_string(error));
          ++compared;
          if (mode == TopologyMode::none && error == ErrorIndicator::bound) {
            EXPECT_TRUE(a.triangles == b.triangles && a.positions == b.positions) << what << ": the bound is exact";
            continue;
          }
          const double na = static_cast<double>(a.triangles.size()), nb = static_cast<double>(b.triangles.size());
          EXPECT_LE(std::fabs(nb - na), 0.05 * std::max(na, 1.0) + 2) << what;
          differing += a.triangles != b.triangles;
          if (mode == TopologyMode::preserve) {  // both keep the eps-0 topology
            const MeshTopology ta = measure_topology(a), tb = measure_topology(b);
            EXPECT_EQ(ta.components, tb.components) << what;
            EXPECT_EQ(ta.euler_characteristic, tb.euler_characteristic) << what;
          }
        }
  }
  EXPECT_EQ(compared, 6 * 4 * 4 * 2);
  RecordProperty("differing_meshes", differing);
}

}  // namespace
}  // namespace isotope
