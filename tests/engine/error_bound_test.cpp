// What eps means with the default indicator (docs/METHOD.md, "Per-vertex records"): the coarse field
// deviates from the data by at most eps. Its surface is where the coarse field equals the
// isovalue, so at every vertex of an eps mesh the data's own (finest, piecewise linear) field lies
// within eps of the isovalue. Checked on the shared volumes and synthetic fields, from the compact
// hierarchy in memory and from a store, in every topology mode (which only refine more).
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <numeric>
#include <string>

#include "engine/extract/extract_drivers.h"
#include "engine/hierarchy/hierarchy.h"
#include "engine/synthetic/fields.h"
#include "io/store/brick_cache.h"
#include "io/store/paged_volume.h"
#include "io/store/store_reader.h"
#include "tests/support/temp_dir_test.h"
#include "tests/support/test_support.h"

namespace isotope {
namespace {

// The data's piecewise linear field at p (lattice coordinates; spacing 1, origin 0): the Kuhn
// tetrahedron of p's cell around the diagonal from the cell's all-even corner (cell_tetrahedra).
double fine_field(const Volume& v, const std::array<float, 3>& p) {
  std::array<int64_t, 3> c{};
  std::array<double, 3> t{};
  std::array<int64_t, 3> step{};
  for (int a = 0; a < 3; ++a) {
    c[a] = std::clamp<int64_t>(static_cast<int64_t>(std::floor(p[a])), 0, v.dims[a] - 2);
    const double u = p[a] - static_cast<double>(c[a]);
    // The diagonal starts at the even corner: along an axis where the cell starts odd, walk down.
    const bool odd = (c[a] & 1) != 0;
    t[a] = odd ? 1 - u : u;
    step[a] = odd ? -1 : 1;
    if (odd) c[a] += 1;
  }
  std::array<int, 3> order{0, 1, 2};
  std::sort(order.begin(), order.end(), [&](int x, int y) { return t[x] > t[y]; });
  std::array<int64_t, 3> at = c;
  double f = v.at(at[0], at[1], at[2]);
  for (int i = 0; i < 3; ++i) {
    const int a = order[i];
    const double before = v.at(at[0], at[1], at[2]);
    at[a] += step[a];
    f += t[a] * (v.at(at[0], at[1], at[2]) - before);
  }
  return f;
}

// The largest |data - iso| over the mesh's vertices.
double largest_deviation(const Mesh& m, const Volume& v, float iso) {
  double worst = 0;
  for (const auto& p : m.positions) worst = std::max(worst, std::fabs(fine_field(v, p) - iso));
  return worst;
}

class ErrorBound : public testing::TempDirTest {};

TEST_F(ErrorBound, EpsBoundsHowFarTheDataIsFromTheIsovalueAtEveryVertex) {
  struct Case {
    std::string name;
    Volume volume;
    float iso;
  };
  std::vector<Case> cases = {{"noise", testing::crop(generate_noise(45, 5), {45, 39, 41}), 0.1f},
                             {"algebraic", generate_algebraic(65), 0.0f}};
  for (const auto& s : testing::shared_volumes())
    for (float iso : s.isovalues) cases.push_back({s.name, testing::load_shared(s), iso});
  int checked = 0, tight = 0;
  for (Case& c : cases) {
    c.volume.spacing = {1, 1, 1};
    c.volume.origin = {0, 0, 0};
    const Hierarchy memory = Hierarchy::build(c.volume);
    const StoreReader store(testing::write_store(c.volume, dir_.string(), "s"));
    BrickCache cache(store, uint64_t{1} << 30);
    const PagedVolume paged(cache);
    const auto [lo, hi] = std::minmax_element(c.volume.values.begin(), c.volume.values.end());
    // The PL field at a float vertex position: a few float steps of rounding times the gradient.
    const double slack = 1e-4 * (*hi - *lo);
    for (double rel : {0.0, 0.003, 0.02, 0.1, 0.4})
      for (TopologyMode mode : {TopologyMode::none, TopologyMode::preserve, TopologyMode::simplify}) {
        ExtractOptions o;
        o.iso = c.iso, o.eps = rel * (*hi - *lo), o.topology = mode;
        if (mode == TopologyMode::simplify) o.delta = 0.05 * (*hi - *lo);
        const std::string what = c.name + " iso " + std::to_string(c.iso) + " eps " + std::to_string(o.eps) + " " +
                                 std::string(to_string(mode));
        const Mesh a = extract(memory, o), b = extract(paged, o);
        ASSERT_FALSE(a.positions.empty()) << what;
        const double deviation = largest_deviation(a, c.volume, c.iso);
        EXPECT_LE(deviation, o.eps + slack) << what;
        EXPECT_LE(largest_deviation(b, c.volume, c.iso), o.eps + slack) << what << " (store)";
        tight += deviation > 0.5 * o.eps && o.eps > 0;  // the bound is not vacuous everywhere
        ++checked;
      }
  }
  EXPECT_EQ(checked, static_cast<int>(cases.size()) * 15);
  EXPECT_GT(tight, 0) << "somewhere the data comes close to eps from the isovalue";
}

}  // namespace
}  // namespace isotope
