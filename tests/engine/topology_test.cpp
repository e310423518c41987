// Topology preservation (docs/DESIGN.md, invariant 4): with the exact rule, components and Euler
// characteristic at every eps equal those at eps = 0; the paper's rule and no control do not.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>
#include <string>
#include <vector>

#include "engine/extract/extract_drivers.h"
#include "engine/hierarchy/critical_rule.h"
#include "engine/hierarchy/critical_table.h"
#include "engine/hierarchy/diamond.h"
#include "engine/hierarchy/multires_volume.h"
#include "engine/synthetic/fields.h"
#include "io/store/store_format.h"
#include "isotope/mesh.h"
#include "tests/support/test_support.h"

namespace isotope {
namespace {

using testing::crop;

struct SweepVolume {
  std::string name;
  Volume volume;
  std::vector<float> isovalues;
};

std::vector<SweepVolume> sweep_volumes() {
  std::vector<SweepVolume> v;
  for (uint64_t seed = 1; seed <= 6; ++seed) {
    v.push_back({"noise17 seed " + std::to_string(seed), generate_noise(17, seed), {-0.3f, -0.1f, 0.1f, 0.3f}});
    v.push_back({"noise 21x19x23 seed " + std::to_string(seed),
                 crop(generate_noise(23, 100 + seed), {21, 19, 23}),
                 {-0.3f, -0.1f, 0.1f, 0.3f}});
  }
  v.push_back({"algebraic 33", generate_algebraic(33), {-0.2f, 0.0f, 0.2f}});
  v.push_back({"algebraic 65 shifted", generate_algebraic(65, {0.15625, 0.09375, 0}), {-0.1f, 0.0f, 0.1f}});
  for (const auto& s : testing::shared_volumes())
    v.push_back({s.name, testing::load_shared(s), {s.isovalues[0], s.isovalues[1], s.isovalues[2]}});
  return v;
}

struct Tally {
  int cases = 0, kept = 0;
  double rate() const { return cases ? static_cast<double>(kept) / cases : 1.0; }
  void add(bool k) {
    ++cases;
    kept += k;
  }
};

struct Sweep {
  Tally all[3];   // per mode: none, paper, preserve
  Tally hard[3];  // the cases where refining by error alone loses topology
  std::vector<std::string> preserve_failures;

  // One (volume, iso, eps, indicator) case, all three modes against eps = 0.
  void run(const MultiresVolume& mv, const std::string& name, float iso, double eps, ErrorIndicator err,
           const MeshTopology& ref) {
    bool none_kept = true;
    for (TopologyMode mode : {TopologyMode::none, TopologyMode::paper, TopologyMode::preserve}) {
      ExtractOptions o;
      o.iso = iso;
      o.eps = eps;
      o.error = err;
      o.topology = mode;
      const MeshTopology t = measure_topology(extract(mv, o));
      const bool kept = t.components == ref.components && t.euler_characteristic == ref.euler_characteristic;
      const int m = static_cast<int>(mode);
      if (mode == TopologyMode::none) none_kept = kept;
      all[m].add(kept);
      if (!none_kept) hard[m].add(kept);
      if (mode == TopologyMode::preserve && !kept)
        preserve_failures.push_back(
            name + " iso " + std::to_string(iso) + " eps " + std::to_string(eps) + " " + std::string(to_string(err)) +
            ": components " + std::to_string(t.components) + " vs " + std::to_string(ref.components) + ", chi " +
            std::to_string(t.euler_characteristic) + " vs " + std::to_string(ref.euler_characteristic));
    }
  }
};

TEST(TopologyPreservation, ExactRuleKeepsComponentsAndEulerCharacteristicEverywhere) {
  Sweep sweep;
  for (const SweepVolume& sv : sweep_volumes()) {
    const MultiresVolume mv = MultiresVolume::build(sv.volume);
    const auto [lo, hi] = std::minmax_element(sv.volume.values.begin(), sv.volume.values.end());
    for (float iso : sv.isovalues) {
      ExtractOptions full;
      full.iso = iso;
      const MeshTopology ref = measure_topology(extract(mv, full));
      for (double rel : {0.002, 0.01, 0.04, 0.15, 0.5, 2.0})
        for (ErrorIndicator err : {ErrorIndicator::bound, ErrorIndicator::surplus})
          sweep.run(mv, sv.name, iso, rel * (*hi - *lo), err, ref);
    }
  }
  const Tally* all = sweep.all;
  std::printf("topology kept in %d cases each: none %.1f%%, paper %.1f%%, preserve %.1f%%\n", all[0].cases,
              100 * all[0].rate(), 100 * all[1].rate(), 100 * all[2].rate());
  std::printf("where none loses topology (%d cases): paper keeps it in %.1f%%, preserve in %.1f%%\n",
              sweep.hard[0].cases, 100 * sweep.hard[1].rate(), 100 * sweep.hard[2].rate());
  for (const auto& f : sweep.preserve_failures) ADD_FAILURE() << f;
  EXPECT_GE(all[2].cases, 300);
  // The sweep must be able to tell the modes apart, or it proves nothing about preserve.
  EXPECT_LT(all[0].rate(), 0.97);
  EXPECT_LT(all[1].rate(), 0.99);
  EXPECT_GE(sweep.hard[0].cases, 50);
}

// The design notes' smallest case (docs/METHOD.md, "What the tests measured"): a 3x3x3 grid whose root cube diamond the
// paper calls regular, although refining it splits one component into two at iso 0.8585. Every finer vertex has zero
// surplus, so the field at full resolution is the once-refined one.
Volume paper_counterexample() {
  const Lattice lattice = Lattice::enclosing({3, 3, 3});
  Volume v;
  v.dims = {3, 3, 3};
  v.values.assign(27, 0.0f);
  auto set = [&](Coord c, float f) { v.values[v.index(c[0], c[1], c[2])] = f; };
  const Diamond root = diamond_of({1, 1, 1}, lattice);
  set(root.v, 0.449f);
  set(root.a, 0.895f);
  set(root.b, 0.951f);
  const float ring[6] = {0.845f, 0.507f, 0.236f, 0.019f, 0.325f, 0.437f};
  for (int i = 0; i < 6; ++i) set(root.ring[i], ring[i]);
  for (int level = 1; level < lattice.max_level(); ++level)
    for (int64_t i = 0; i < 27; ++i) {
      const Coord c = lattice.coord(i);
      if (c == Coord{1, 1, 1} || (c[0] % 2 == 0 && c[1] % 2 == 0 && c[2] % 2 == 0)) continue;
      const Diamond d = diamond_of(c, lattice);
      if (d.level == level) set(c, 0.5f * (v.at(d.a[0], d.a[1], d.a[2]) + v.at(d.b[0], d.b[1], d.b[2])));
    }
  return v;
}

TEST(PaperRule, MissesTheRootCubeCounterexampleThatTheExactRuleCatches) {
  const Volume v = paper_counterexample();
  const Lattice lattice = Lattice::enclosing(v.dims);
  const Diamond root = diamond_of({1, 1, 1}, lattice);
  DiamondValues dv;
  dv.type = root.type;
  dv.fa = 0.895f;
  dv.fb = 0.951f;
  dv.fv = 0.449f;
  for (int i = 0; i < 6; ++i) dv.ring[i] = v.at(root.ring[i][0], root.ring[i][1], root.ring[i][2]);
  const float iso = 0.8585f;
  EXPECT_FALSE(is_critical_pattern(dv.type, sign_pattern(dv, dv.fv))) << "the paper's table at f(v)";
  EXPECT_TRUE(paper_interval(dv).empty());
  EXPECT_TRUE(exact_rule_fires(dv, iso)) << "the pattern relative to the isovalue is critical";
  EXPECT_TRUE(exact_interval(dv).contains(iso));

  const MultiresVolume mv = MultiresVolume::build(v);
  ExtractOptions o;
  o.iso = iso;
  const MeshTopology full = measure_topology(extract(mv, o));
  EXPECT_EQ(full.components, 2);
  o.eps = 10;  // coarse enough that only topology control can refine
  o.topology = TopologyMode::paper;
  EXPECT_EQ(measure_topology(extract(mv, o)).components, 1) << "the paper's rule merges the two components";
  o.topology = TopologyMode::none;
  EXPECT_EQ(measure_topology(extract(mv, o)).components, 1);
  o.topology = TopologyMode::preserve;
  const MeshTopology kept = measure_topology(extract(mv, o));
  EXPECT_EQ(kept.components, full.components);
  EXPECT_EQ(kept.euler_characteristic, full.euler_characteristic);
}

// The noise field is the sum of its Gaussians, each evaluated as a product of one per axis; its
// bytes are pinned: those the sum of exps of the squared distance gave (isotope generate noise,
// seed 1, 24 bumps, the same file at 33^3, 65^3, 100^3 and 257^3; and as uint8 at 513^3), so a
// change to the field, which every noise test and the bench's noise rows stand on, shows here.
TEST(NoiseField, IsTheSumOfItsGaussiansAsPinnedAndSpansMinusOneToOne) {
  const Volume v = generate_noise(33, 1);
  EXPECT_EQ(store_checksum(v.values.data(), v.values.size() * sizeof(float)), 12471118103791512364ull);
  const auto [lo, hi] = std::minmax_element(v.values.begin(), v.values.end());
  EXPECT_EQ(*lo, -1.0f);
  EXPECT_EQ(*hi, 1.0f);
  EXPECT_TRUE(generate_noise(33, 2).values != v.values) << "another seed, another field";
}

// The paper's Table 1 setting and its shifted variant (the demo's): at the paper's
// setting every mode keeps the one component; shifted, the modes part.
TEST(AlgebraicFunction, ShiftedSingularityPartsTheModesAndPreserveKeepsOneComponent) {
  const MultiresVolume mv = MultiresVolume::build(generate_algebraic(65, {0.15625, 0.09375, 0}));
  ExtractOptions o;
  const MeshTopology full = measure_topology(extract(mv, o));
  ASSERT_EQ(full.components, 1);
  int none_wrong = 0, paper_wrong = 0;
  for (double eps : {1.0 / 64, 1.0 / 16, 0.25, 1.0}) {
    o.eps = eps;
    o.topology = TopologyMode::preserve;
    const MeshTopology p = measure_topology(extract(mv, o));
    EXPECT_EQ(p.components, 1) << "eps " << eps;
    EXPECT_EQ(p.euler_characteristic, full.euler_characteristic) << "eps " << eps;
    o.topology = TopologyMode::paper;
    paper_wrong += measure_topology(extract(mv, o)).components != 1;
    o.topology = TopologyMode::none;
    none_wrong += measure_topology(extract(mv, o)).components != 1;
  }
  EXPECT_GE(paper_wrong, 2);
  EXPECT_GE(none_wrong, 2);
}

}  // namespace
}  // namespace isotope
