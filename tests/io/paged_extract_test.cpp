// Out-of-core extraction (PagedVolume, BrickCache): a store paged through a brick
// cache gives the in-memory mesh bit for bit, whatever the threads and the cache budget; closed
// surfaces stay closed and keep their topology through the paged, parallel path; a focus is full
// resolution at its point; a triangle budget takes the finest eps that fits; the cache reads each
// brick at most once when the store fits and stays near its budget when it does not; a corrupt
// brick is named, never a crash. The PagedParallel tests, small versions of the parallel ones,
// also run under ThreadSanitizer in CI.
#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <optional>
#include <random>
#include <set>
#include <span>
#include <stdexcept>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "engine/extract/adaptive_extract.h"
#include "engine/extract/budget_memo.h"
#include "engine/extract/extract_drivers.h"
#include "engine/extract/finest_extract.h"
#include "engine/hierarchy/compact_record.h"
#include "engine/hierarchy/hierarchy.h"
#include "engine/synthetic/fields.h"
#include "io/store/brick_cache.h"
#include "io/store/held_words.h"
#include "io/store/paged_volume.h"
#include "io/store/store_format.h"
#include "io/store/store_reader.h"
#include "io/store/store_writer.h"
#include "io/volume/box_reader.h"
#include "io/volume/raw_reader.h"
#include "isotope/error.h"
#include "isotope/mesh.h"
#include "isotope/source.h"
#include "tests/support/byte_files.h"
#include "tests/support/temp_dir_test.h"
#include "tests/support/test_support.h"

namespace isotope {
namespace {

// The smallest budget there is. BrickCache raises it to its floor (BrickCache::budget_bytes), a
// few bricks, so with it the cache holds as little as it ever does and evicts on every store here
// whose extraction touches more bricks than that.
constexpr uint64_t kTinyBudget = 1;
constexpr uint64_t kHugeBudget = uint64_t{1} << 30;  // every store here fits many times over
constexpr double kInf = std::numeric_limits<double>::infinity();

// What a float32 raw file carries (and so the store): unit spacing, origin 0. Output coordinates
// are then lattice coordinates, which the focus tests rely on.
Volume as_raw(Volume v) {
  v.spacing = {1, 1, 1};
  v.origin = {0, 0, 0};
  return v;
}

std::string describe(const ExtractOptions& o) {
  std::string s = "iso " + std::to_string(o.iso) + " eps " + std::to_string(o.eps) + " " +
                  std::string(to_string(o.topology)) + " " + std::string(to_string(o.error));
  if (o.focus)
    s += " focus (" + std::to_string(o.focus->point[0]) + " " + std::to_string(o.focus->point[1]) + " " +
         std::to_string(o.focus->point[2]) + ") r " + std::to_string(o.focus->radius);
  if (o.max_triangles > 0) s += " max_triangles " + std::to_string(o.max_triangles);
  return s;
}

// Equal positions and triangles, bit for bit.
::testing::AssertionResult same_mesh(const Mesh& a, const Mesh& b) {
  if (a.positions.size() != b.positions.size() || a.triangles.size() != b.triangles.size())
    return ::testing::AssertionFailure() << "sizes differ: " << a.positions.size() << " vertices, "
                                         << a.triangles.size() << " triangles vs " << b.positions.size()
                                         << " vertices, " << b.triangles.size() << " triangles";
  for (size_t i = 0; i < a.positions.size(); ++i)
    if (std::memcmp(a.positions[i].data(), b.positions[i].data(), sizeof a.positions[i]) != 0)
      return ::testing::AssertionFailure() << "vertex " << i << " differs";
  for (size_t i = 0; i < a.triangles.size(); ++i)
    if (a.triangles[i] != b.triangles[i]) return ::testing::AssertionFailure() << "triangle " << i << " differs";
  return ::testing::AssertionSuccess();
}

// Every directed edge of a closed, consistently oriented surface appears once, and so does its
// reverse (as in the CrackFree tests, with a sorted array for the map).
int64_t orientation_defects(const Mesh& m) {
  std::vector<std::pair<uint32_t, uint32_t>> directed;
  directed.reserve(3 * m.triangles.size());
  for (const auto& t : m.triangles)
    for (int i = 0; i < 3; ++i) directed.push_back({t[i], t[(i + 1) % 3]});
  std::sort(directed.begin(), directed.end());
  auto count = [&](std::pair<uint32_t, uint32_t> e) {
    const auto [first, last] = std::equal_range(directed.begin(), directed.end(), e);
    return last - first;
  };
  int64_t bad = 0;
  for (size_t i = 0; i < directed.size(); ++i) {
    if (i > 0 && directed[i] == directed[i - 1]) continue;
    if (count(directed[i]) != 1 || count({directed[i].second, directed[i].first}) != 1) ++bad;
  }
  return bad;
}

double distance(const std::array<float, 3>& p, const std::array<double, 3>& q) {
  double d2 = 0;
  for (int a = 0; a < 3; ++a) d2 += (p[a] - q[a]) * (p[a] - q[a]);
  return std::sqrt(d2);
}

// Triangles with at least one vertex within r of q.
int64_t triangles_near(const Mesh& m, const std::array<double, 3>& q, double r) {
  int64_t n = 0;
  for (const auto& t : m.triangles)
    n += distance(m.positions[t[0]], q) <= r || distance(m.positions[t[1]], q) <= r ||
         distance(m.positions[t[2]], q) <= r;
  return n;
}

std::pair<float, float> value_range(const Volume& v) {
  const auto [lo, hi] = std::minmax_element(v.values.begin(), v.values.end());
  return {*lo, *hi};
}

struct PagedRun {
  Mesh mesh;
  ExtractStats stats;
  BrickCacheStats cache;
  uint64_t budget = 0;  // the cache's, which may raise the one asked for (BrickCache::budget_bytes)
};

// One extraction through a fresh cache of `budget` bytes (threads: as the caller limits them).
PagedRun run_paged(const StoreReader& store, uint64_t budget, const ExtractOptions& o) {
  BrickCache cache(store, budget);
  const PagedVolume volume(cache);
  PagedRun r;
  r.mesh = extract(volume, o, &r.stats);
  r.cache = cache.stats();
  r.budget = cache.budget_bytes();
  EXPECT_GE(r.budget, budget);
  return r;
}

// Decoded sizes of a store's bricks as the cache counts them, every field decoded: all of them,
// and the largest.
struct DecodedSizes {
  uint64_t total = 0, largest = 0;
};
DecodedSizes decoded_sizes(const StoreReader& store) {
  BrickCache cache(store, kHugeBudget);  // nothing is evicted: the peak grows by each brick's size
  DecodedSizes d;
  for (int64_t i = 0; i < store.layout().brick_count(); ++i) {
    cache.require(*cache.get(i), i, RecordFields{true, true, true, true});
    const uint64_t now = cache.stats().peak_bytes;
    d.largest = std::max(d.largest, now - d.total);
    d.total = now;
  }
  return d;
}

class PagedTest : public testing::TempDirTest {
 protected:
  // Writes `v` as float32 raw and converts it (as the store tests do); returns the store's path.
  std::string convert(const Volume& v, const std::string& name, int brick_bits = kDefaultBrickBits,
                      int quantize_bits = 0) {
    ConvertOptions o;
    o.brick_bits = brick_bits;
    o.quantize_bits = quantize_bits;
    return testing::write_store(v, dir_.string(), name, o);
  }
  void expect_corrupt_bricks_named(size_t stride, const std::vector<std::pair<size_t, uint64_t>>& schedule);
};
using PagedExtract = PagedTest;
using PagedParallel = PagedTest;  // small enough for ThreadSanitizer in CI

// 1. Paged = in-memory, bit for bit, over volumes, brick sizes, isovalues, eps, modes and error
// indicators, through a generous cache and through the smallest one (kTinyBudget).
class PagedEqualsInMemory : public PagedTest {
 protected:
  struct Sweep {
    std::vector<float> isovalues;
    std::vector<double> relative_eps;  // of the data range
    std::vector<TopologyMode> modes;
    std::vector<ErrorIndicator> errors;
  };
  // Compares every combination of `sweep` on a store of `v` with `bits`, through `budget`'s cache
  // (one cache for the whole sweep); returns the number of comparisons.
  int compare(const std::string& name, const Volume& v, int bits, uint64_t budget, const Sweep& sweep) {
    const Hierarchy memory = Hierarchy::build(v);
    const auto [lo, hi] = value_range(v);
    const StoreReader store(convert(v, name + std::to_string(bits), bits));
    BrickCache cache(store, budget);
    const PagedVolume paged(cache);
    int compared = 0, nonempty = 0;
    for (float iso : sweep.isovalues)
      for (double rel : sweep.relative_eps)
        for (TopologyMode mode : sweep.modes)
          for (ErrorIndicator error : sweep.errors) {
            ExtractOptions o;
            o.iso = iso, o.eps = rel * (hi - lo), o.topology = mode, o.error = error;
            if (mode == TopologyMode::simplify) {  // a weight per indicator, a delta that drops some points
              o.weight = error == ErrorIndicator::bound ? SimplificationWeight::interval : SimplificationWeight::size;
              o.delta = error == ErrorIndicator::bound ? 0.02 * (hi - lo) : 512;
            }
            const Mesh expected = extract(memory, o);
            nonempty += !expected.triangles.empty();
            EXPECT_TRUE(same_mesh(expected, extract(paged, o)))
                << name << " brick bits " << bits << " cache budget " << budget << " " << describe(o);
            ++compared;
          }
    EXPECT_GT(nonempty, compared * 3 / 4) << name;
    const BrickCacheStats stats = cache.stats();
    EXPECT_GT(stats.bricks_read, 0) << name;
    if (budget == kHugeBudget) {  // each brick read at most once
      EXPECT_LE(stats.bricks_read, store.layout().brick_count()) << name;
    }
    return compared;
  }
  const std::vector<TopologyMode> all_modes_ = {TopologyMode::none, TopologyMode::paper, TopologyMode::preserve};
  const std::vector<TopologyMode> with_simplify_ = {TopologyMode::none, TopologyMode::paper, TopologyMode::preserve,
                                                    TopologyMode::simplify};
  const std::vector<ErrorIndicator> both_errors_ = {ErrorIndicator::bound, ErrorIndicator::surplus};
};

// Odd dimensions, brick bits 3 and 5, every combination (simplify too), through a generous cache and through
// the smallest one, and through the smallest with brick bits 4 too (the 5-bit stores of these
// volumes fit within the cache's floor).
TEST_F(PagedEqualsInMemory, SyntheticVolumesBitForBit) {
  const Volume noise = as_raw(testing::crop(generate_noise(40, 11), {37, 29, 23}));
  const Volume algebraic = as_raw(testing::crop(generate_algebraic(40, {5.0 / 32, 3.0 / 32, 0}), {33, 40, 35}));
  const std::vector<double> eps = {0.0, 0.01, 0.2};
  int compared = 0;
  for (int bits : {3, 5}) {
    compared += compare("noise", noise, bits, kHugeBudget, {{-0.3f, 0.0f, 0.25f}, eps, with_simplify_, both_errors_});
    compared += compare("algebraic", algebraic, bits, kHugeBudget, {{0.0f, 0.1f}, eps, with_simplify_, both_errors_});
  }
  for (int bits : {3, 4, 5}) {
    compared += compare("noise", noise, bits, kTinyBudget, {{-0.3f, 0.0f, 0.25f}, eps, all_modes_, both_errors_});
    compared += compare("algebraic", algebraic, bits, kTinyBudget, {{0.0f, 0.1f}, eps, all_modes_, both_errors_});
  }
  EXPECT_EQ(compared, 2 * 24 * (3 + 2) + 3 * 18 * (3 + 2));
}

// The four shared volumes: every combination through a generous cache (default bricks); through
// the smallest cache on brick bits 3, where pieces of the traversal decode their bricks afresh
// (slow on these sizes), one isovalue and one error indicator.
TEST_F(PagedEqualsInMemory, SharedVolumesBitForBit) {
  int compared = 0;
  for (const auto& s : testing::shared_volumes()) {
    const Volume v = testing::load_shared(s);
    compared += compare(s.name, v, 5, kHugeBudget,
                        {{s.isovalues[0], s.isovalues[1], s.isovalues[2]}, {0.0, 0.01, 0.2}, all_modes_, both_errors_});
    compared +=
        compare(s.name, v, 3, kTinyBudget, {{s.isovalues[1]}, {0.0, 0.01, 0.2}, all_modes_, {ErrorIndicator::bound}});
  }
  EXPECT_EQ(compared, 4 * (54 + 9));
}

// 2. One mesh, byte for byte, for 1, 2, 4 and 8 threads and cache budgets of kTinyBudget, an
// eighth of the decoded store and 1 GB, with simplification, a focus and a triangle budget; the in-memory mesh
// and statistics too; and the cache's peak within its guarantee (see test 6) on every run.
void expect_same_bytes(const std::string& name, const Volume& v, float iso, const StoreReader& store,
                       const std::vector<size_t>& thread_counts = {1, 2, 4, 8}) {
  const Hierarchy memory = Hierarchy::build(v);
  const auto [lo, hi] = value_range(v);
  const DecodedSizes sizes = decoded_sizes(store);
  ASSERT_GT(sizes.total / 8, sizes.largest) << name << ": an eighth of the store must not hold everything";
  ExtractOptions full;
  full.iso = iso;
  const auto full_triangles = static_cast<int64_t>(extract(memory, full).triangles.size());
  ASSERT_GT(full_triangles, 1000) << name;
  ExtractOptions coarsest = full;
  coarsest.eps = kInf;
  const auto coarsest_triangles = static_cast<int64_t>(extract(memory, coarsest).triangles.size());

  std::vector<ExtractOptions> variants(3);
  variants[0].iso = iso, variants[0].eps = 0.05 * (hi - lo);
  variants[0].topology = TopologyMode::simplify, variants[0].delta = 0.01 * (hi - lo);
  variants[1].iso = iso, variants[1].eps = 0.3 * (hi - lo), variants[1].topology = TopologyMode::paper;
  const std::array<double, 3> dims = {static_cast<double>(v.dims[0]), static_cast<double>(v.dims[1]),
                                      static_cast<double>(v.dims[2])};
  variants[1].focus = Focus{{dims[0] / 2, dims[1] / 3, dims[2] / 2}, dims[0] / 4};
  variants[2].iso = iso, variants[2].error = ErrorIndicator::surplus;
  variants[2].max_triangles = coarsest_triangles + (full_triangles - coarsest_triangles) / 3;  // above the floor
  for (const ExtractOptions& o : variants) {
    ExtractStats expected_stats;
    const Mesh expected = extract(memory, o, &expected_stats);
    ASSERT_GT(expected.triangles.size(), 0u);
    for (size_t threads : thread_counts) {
      const tbb::global_control limit(tbb::global_control::max_allowed_parallelism, threads);
      for (uint64_t budget : {kTinyBudget, sizes.total / 8, kHugeBudget}) {
        const PagedRun r = run_paged(store, budget, o);
        const std::string what =
            name + " " + describe(o) + " threads " + std::to_string(threads) + " budget " + std::to_string(budget);
        ASSERT_TRUE(same_mesh(expected, r.mesh)) << what;
        EXPECT_EQ(r.stats.chosen_eps, expected_stats.chosen_eps) << what;
        EXPECT_EQ(r.stats.next_eps, expected_stats.next_eps) << what;
        EXPECT_EQ(r.stats.next_triangles, expected_stats.next_triangles) << what;
        EXPECT_EQ(r.stats.tets_simplified, expected_stats.tets_simplified) << what;
        EXPECT_EQ(r.stats.budget_steps, expected_stats.budget_steps) << what;
        EXPECT_EQ(r.stats.tets_emitted, expected_stats.tets_emitted) << what;
        EXPECT_LE(r.cache.peak_bytes, std::max(r.budget, sizes.largest) + sizes.largest) << what;
      }
    }
  }
}

TEST_F(PagedExtract, SameBytesForAnyThreadsAndCacheBudget) {
  const Volume hydrogen = testing::load_shared(testing::shared_volumes()[2]);
  expect_same_bytes("hydrogen", hydrogen, 0.05f, StoreReader(convert(hydrogen, "hydrogen", 4)));
  const Volume noise = as_raw(testing::crop(generate_noise(50, 7), {47, 41, 45}));
  expect_same_bytes("noise", noise, 0.1f, StoreReader(convert(noise, "noise", 3)));
}

// The same on a small volume with small bricks and 2 and 8 threads, so that threads contend for
// the cache's slots and locks: the one CI runs under ThreadSanitizer.
TEST_F(PagedParallel, SameBytesForAnyThreadsAndCacheBudget) {
  const Volume noise = as_raw(testing::crop(generate_noise(40, 7), {29, 23, 27}));
  expect_same_bytes("noise", noise, 0.1f, StoreReader(convert(noise, "noise", 3)), {2, 8});
}

// 3. Invariant 3 of docs/DESIGN.md through the paged, parallel path: the closed shapes of
// the CrackFree tests, converted to stores with small bricks and read through a cache of
// an eighth of their decoded size on 4 threads, stay closed, manifold and oriented at every eps,
// with a focus anywhere (inside, on the corner, outside the volume) and with a triangle budget;
// at eps 0, and in preserve mode always, they keep their components and Euler characteristic.
TEST_F(PagedExtract, ClosedShapesStayClosedManifoldAndKeepTheirTopology) {
  struct Shape {
    const char* name;
    Volume volume;
    int64_t components, euler;
  };
  const Shape shapes[] = {
      {"sphere 33", as_raw(generate_sphere(33)), 1, 2},
      {"torus 41", as_raw(generate_torus(41)), 1, 0},
      {"linked tori 33", as_raw(generate_linked_tori(33)), 2, 0},
      {"nested spheres 45", as_raw(generate_nested_spheres(45)), 3, 6},
  };
  const tbb::global_control limit(tbb::global_control::max_allowed_parallelism, 4);
  int checked = 0;
  for (const Shape& s : shapes) {
    const StoreReader store(convert(s.volume, "shape", 3));
    BrickCache cache(store, std::max<uint64_t>(decoded_sizes(store).total / 8, 1));
    const PagedVolume paged(cache);
    auto check = [&](const ExtractOptions& o, bool topology_known) {
      const Mesh m = extract(paged, o);
      const MeshTopology t = measure_topology(m);
      const std::string what = std::string(s.name) + " " + describe(o);
      EXPECT_EQ(t.boundary_edges, 0) << what;
      EXPECT_EQ(t.nonmanifold_edges, 0) << what;
      EXPECT_EQ(orientation_defects(m), 0) << what;
      if (topology_known) {
        EXPECT_EQ(t.components, s.components) << what;
        EXPECT_EQ(t.euler_characteristic, s.euler) << what;
      }
      if (o.max_triangles > 0) {
        EXPECT_LE(t.triangles, o.max_triangles) << what;
      }
      ++checked;
    };
    for (double eps : {0.0, 0.02, 0.5, 5.0})
      for (ErrorIndicator err : {ErrorIndicator::bound, ErrorIndicator::surplus})
        for (TopologyMode mode : {TopologyMode::none, TopologyMode::paper, TopologyMode::preserve}) {
          if (eps == 0.0 && err == ErrorIndicator::surplus) continue;  // eps 0 refines everything either way
          ExtractOptions o;
          o.eps = eps, o.error = err, o.topology = mode;
          check(o, eps == 0.0 || mode == TopologyMode::preserve);
        }
    const double n = static_cast<double>(s.volume.dims[0] - 1);
    const std::array<double, 3> points[] = {
        {n / 2, n / 2, n / 2}, {n / 2 + 1.3, n / 4, n / 2 - 0.7}, {0, 0, 0}, {-15, n + 20, n / 2}};
    for (const auto& p : points)
      for (double radius : {3.0, 12.0, 60.0})
        for (TopologyMode mode : {TopologyMode::none, TopologyMode::paper, TopologyMode::preserve}) {
          ExtractOptions o;
          o.eps = 0.5, o.topology = mode, o.focus = Focus{p, radius};
          check(o, mode == TopologyMode::preserve);
        }
    for (TopologyMode mode : {TopologyMode::none, TopologyMode::paper, TopologyMode::preserve}) {
      ExtractOptions o;
      o.topology = mode;
      const auto full = static_cast<int64_t>(extract(paged, o).triangles.size());
      o.eps = kInf;  // the coarsest mesh the mode allows
      const auto coarsest = static_cast<int64_t>(extract(paged, o).triangles.size());
      o.eps = 0;
      for (double fraction : {0.25, 0.6}) {
        o.max_triangles = std::max<int64_t>({coarsest, static_cast<int64_t>(fraction * static_cast<double>(full)), 1});
        check(o, mode == TopologyMode::preserve);
        o.focus = Focus{points[1], 8.0};  // a focus and a budget together
        check(o, mode == TopologyMode::preserve);
        o.focus.reset();
      }
    }
  }
  EXPECT_EQ(checked, 4 * (21 + 36 + 12));
}

// 4. A focus: full resolution at the point, finer near it than without, nothing changed by a
// focus far away, and the mesh always between the plain eps mesh and the eps 0 one.
TEST_F(PagedExtract, FocusIsFullResolutionAtItsPoint) {
  // 65^3: the lattice is the data box, so no tetrahedron is clipped and a refinement never loses
  // triangles (a bisection never lowers the count of marching tetrahedra's triangles).
  const Volume v = as_raw(generate_noise(65, 3));
  const Hierarchy memory = Hierarchy::build(v);
  const StoreReader store(convert(v, "noise", 4));
  const tbb::global_control limit(tbb::global_control::max_allowed_parallelism, 2);
  BrickCache cache(store, decoded_sizes(store).total / 8);
  const PagedVolume paged(cache);
  int tried = 0;
  for (float iso : {0.0f, 0.2f}) {
    ExtractOptions full;
    full.iso = iso;
    const Mesh eps0 = extract(memory, full);
    ASSERT_GT(eps0.triangles.size(), 1000u);
    // Focus points on the surface: the eps 0 vertices nearest three chosen places.
    std::vector<std::array<double, 3>> points;
    const std::array<double, 3> targets[] = {{32, 32, 32}, {10, 50, 20}, {60, 5, 40}};
    for (const auto& target : targets) {
      size_t best = 0;
      for (size_t i = 1; i < eps0.positions.size(); ++i)
        if (distance(eps0.positions[i], target) < distance(eps0.positions[best], target)) best = i;
      points.push_back({eps0.positions[best][0], eps0.positions[best][1], eps0.positions[best][2]});
    }
    for (const auto& p : points)
      for (TopologyMode mode : {TopologyMode::none, TopologyMode::paper, TopologyMode::preserve})
        for (ErrorIndicator error : {ErrorIndicator::bound, ErrorIndicator::surplus}) {
          constexpr double kRadius = 12;
          ExtractOptions plain = full;
          plain.eps = 0.3, plain.topology = mode, plain.error = error;
          ExtractOptions focused = plain;
          focused.focus = Focus{p, kRadius};
          const std::string what = describe(focused);
          const Mesh coarse = extract(memory, plain), fine = extract(memory, focused);
          ASSERT_TRUE(same_mesh(fine, extract(paged, focused))) << what << ": paged";

          // Finer near the point: more triangles with a vertex within R/2.
          EXPECT_GT(triangles_near(fine, p, kRadius / 2), triangles_near(coarse, p, kRadius / 2)) << what;
          // Full resolution at the point. An eps 0 triangle with a vertex x within 0.25 of p lies
          // in a leaf; each of the leaf's ancestors at level l holds x, so its refinement vertex
          // lies within D(l) + 0.25 of p, D(l) being the farthest a point of a level-l
          // tetrahedron is from its refinement vertex. D(l) + 0.25 < reach(l) (SplitRule's focus)
          // at every level: at the last one above the leaves D = sqrt(2), reach = sqrt(3); higher
          // up the margin only grows. So every ancestor has focus factor 0, an infinite key, and
          // is refined: the triangle is in the focused mesh.
          const auto fine_set = testing::triangle_set(fine);
          int64_t local = 0;
          for (const auto& t : eps0.triangles) {
            if (distance(eps0.positions[t[0]], p) > 0.25 && distance(eps0.positions[t[1]], p) > 0.25 &&
                distance(eps0.positions[t[2]], p) > 0.25)
              continue;
            Mesh one;
            one.positions = {eps0.positions[t[0]], eps0.positions[t[1]], eps0.positions[t[2]]};
            one.triangles = {{0, 1, 2}};
            EXPECT_TRUE(std::binary_search(fine_set.begin(), fine_set.end(), testing::triangle_set(one)[0]))
                << what << ": an eps 0 triangle at the point is missing";
            ++local;
          }
          EXPECT_GE(local, 3) << what << ": the point is an eps 0 vertex, so its triangles are there";
          // Keys only grow with a focus, so the focused mesh refines the plain one and is refined
          // by eps 0's; refining never lowers the triangle count. (A far-away density bound is
          // not guaranteed: the distance is conservative by reach(level), which for coarse levels
          // spans the whole volume, so nothing sharper than this and the far-focus test below.)
          EXPECT_LE(coarse.triangles.size(), fine.triangles.size()) << what;
          EXPECT_LE(fine.triangles.size(), eps0.triangles.size()) << what;
          EXPECT_LT(coarse.triangles.size(), eps0.triangles.size() / 4) << what << ": eps must be coarse here";
          ++tried;
        }
    // A focus with eps 0 is eps 0; a focus farther than reach(0) + radius from every diamond (the
    // whole lattice's refinement edges sum to well under 2000) changes nothing.
    ExtractOptions o = full;
    o.focus = Focus{points[0], 5};
    EXPECT_TRUE(same_mesh(eps0, extract(memory, o))) << "focus with eps 0";
    o.eps = 0.3;
    o.focus = Focus{{-3000, 40, 4000}, 7};
    ExtractOptions plain = o;
    plain.focus.reset();
    EXPECT_TRUE(same_mesh(extract(memory, plain), extract(paged, o))) << "far focus";
  }
  EXPECT_EQ(tried, 2 * 3 * 3 * 2);
}

// v's values as a * v + b.
Volume rescaled(Volume v, float a, float b) {
  for (float& x : v.values) x = a * x + b;
  return v;
}

// 5. A triangle budget: the mesh fits, it is exactly the plain mesh at the chosen eps, the next
// finer eps step gives next_triangles > budget, a budget above the full mesh gives the full mesh,
// and a budget below the coarsest mesh the mode allows (the eps = infinity mesh) throws. In memory,
// paged, and paged from a quantized store (eps reported in data units, not codes).
TEST_F(PagedExtract, TriangleBudgetTakesTheFinestEpsThatFits) {
  struct Case {
    std::string name;
    Volume volume;
    float iso;
    int quantize_bits;
  };
  const Case cases[] = {
      {"noise", as_raw(testing::crop(generate_noise(50, 17), {45, 50, 39})), 0.05f, 0},
      {"neghip", testing::load_shared(testing::shared_volumes()[1]), 32.5f, 0},
      {"hydrogen q8", testing::load_shared(testing::shared_volumes()[2]), 0.05f, 8},
      // The same over a range whose code step is no round number: a budget's eps, reported in
      // the data's units, must select the same keys when it is given back (docs/FORMAT.md).
      {"hydrogen q8 over [-1013, 2259]",
       rescaled(testing::load_shared(testing::shared_volumes()[2]), 3271.9f, -1013.37f), 0.05f * 3271.9f - 1013.37f, 8},
      {"sphere 33", as_raw(generate_sphere(33)), 0.0f, 0},  // 2^k + 1: nothing leaves the data box
  };
  int budgets_run = 0, thrown = 0, ties_chosen = 0;
  for (const Case& c : cases) {
    const Hierarchy memory = Hierarchy::build(c.volume);
    const StoreReader store(convert(c.volume, "budget", 4, c.quantize_bits));
    BrickCache cache(store, kHugeBudget);
    const PagedVolume paged(cache);
    // A quantized store holds other values than the volume: compare it only with itself.
    const bool with_memory = c.quantize_bits == 0;
    for (TopologyMode mode : {TopologyMode::none, TopologyMode::preserve}) {
      ExtractOptions base;
      base.iso = c.iso, base.topology = mode;
      const Mesh full = extract(paged, base);
      ExtractOptions coarsest_o = base;
      coarsest_o.eps = kInf;
      const auto coarsest = static_cast<int64_t>(extract(paged, coarsest_o).triangles.size());
      const auto n = static_cast<int64_t>(full.triangles.size());
      ASSERT_GT(n, 1000) << c.name;
      RecordProperty(c.name + " " + std::string(to_string(mode)) + " coarsest", std::to_string(coarsest));
      // Mode none stops at the 6 root tetrahedra, at most 12 triangles, on any lattice: where
      // the data box is smaller, they reach past it and are clipped to it, each triangle into at
      // most 8 (docs/METHOD.md, "Volumes that are not (2^k+1)^3"). The sphere misses their
      // corners. Preserve refines what reaches past the box, and keeps the sphere a sphere.
      if (mode == TopologyMode::none) {
        EXPECT_LE(coarsest, c.name == "sphere 33" ? 1 : 12 * 8) << c.name;
      } else {
        EXPECT_GT(coarsest, 1) << c.name << " " << to_string(mode);
      }
      std::vector<int64_t> budgets = {n / 10, 3 * n / 10, 7 * n / 10, n + 100, coarsest};
      if (coarsest > 1) budgets.push_back(coarsest - 1);
      budgets.push_back(1);
      for (int64_t budget : budgets) {
        if (budget < 1) continue;  // 0 means no budget
        ExtractOptions o = base;
        o.max_triangles = budget;
        const std::string what = c.name + " " + describe(o) + " (coarsest " + std::to_string(coarsest) + ")";
        if (budget < coarsest) {
          EXPECT_THROW(extract(paged, o), std::runtime_error) << what;
          if (with_memory) {
            EXPECT_THROW(extract(memory, o), std::runtime_error) << what;
          }
          ++thrown;
          continue;
        }
        ExtractStats s;
        Mesh m;
        ASSERT_NO_THROW(m = extract(paged, o, &s)) << what;
        ++budgets_run;
        EXPECT_LE(static_cast<int64_t>(m.triangles.size()), budget) << what;
        EXPECT_GE(s.chosen_eps, 0) << what;
        if (with_memory) {
          ExtractStats ms;
          EXPECT_TRUE(same_mesh(m, extract(memory, o, &ms))) << what << ": in memory";
          EXPECT_EQ(ms.chosen_eps, s.chosen_eps) << what;
          EXPECT_EQ(ms.chosen_eps_ties, s.chosen_eps_ties) << what;
          EXPECT_EQ(ms.next_eps, s.next_eps) << what;
          EXPECT_EQ(ms.next_eps_ties, s.next_eps_ties) << what;
          EXPECT_EQ(ms.next_triangles, s.next_triangles) << what;
        }
        // The plain mesh at the chosen eps and tie classes is the budget's mesh.
        ExtractOptions chosen = base;
        chosen.eps = s.chosen_eps, chosen.eps_ties = s.chosen_eps_ties;
        EXPECT_TRUE(same_mesh(m, extract(paged, chosen)))
            << what << ": plain extraction at chosen eps " << s.chosen_eps << ", eps-ties " << s.chosen_eps_ties;
        ties_chosen += s.chosen_eps_ties >= 0;
        if (budget >= n) {
          EXPECT_EQ(s.next_triangles, 0) << what;
          EXPECT_EQ(s.chosen_eps, 0) << what;
          EXPECT_TRUE(same_mesh(m, full)) << what << ": the budget holds the full mesh";
          continue;
        }
        // One step finer does not fit: a smaller eps, or more tie classes of the same one.
        EXPECT_GT(s.next_triangles, budget) << what;
        if (s.next_eps == s.chosen_eps) {
          EXPECT_GE(s.chosen_eps_ties, 0) << what;
          EXPECT_TRUE(s.next_eps_ties == -1 || s.next_eps_ties > s.chosen_eps_ties) << what;
        } else {
          EXPECT_LT(s.next_eps, s.chosen_eps) << what;
        }
        ExtractOptions next = base;
        next.eps = s.next_eps, next.eps_ties = s.next_eps_ties;
        EXPECT_EQ(static_cast<int64_t>(extract(paged, next).triangles.size()), s.next_triangles)
            << what << ": plain extraction at next eps " << s.next_eps << ", eps-ties " << s.next_eps_ties;
      }
    }
  }
  EXPECT_GT(budgets_run, 20);
  EXPECT_GT(thrown, 0);
  EXPECT_GT(ties_chosen, 5);  // steps within a key were taken
}

// 5b. A triangle budget from a sample (BudgetSample): where
// the guess stands, its mesh holds between 90% and 100% of the budget and is the plain mesh at
// the eps and tie classes reported; where it does not, the choice is the exact search's, mesh for
// mesh. Paged = in memory, one thread = two, and a sample too coarse to be trusted falls back.
// Volumes over 257 a side sample by default, smaller ones never.
TEST_F(PagedExtract, TriangleBudgetFromASampleLandsWithinTenPercentOrFallsBack) {
  Lattice small, large;
  small.k = 8, large.k = 9;
  EXPECT_TRUE(budget_sample_for(small).exact());
  EXPECT_FALSE(budget_sample_for(large).exact());
  const std::string path = std::string(ISOTOPE_TEST_DATA) + "/embryo_256x256x256_uint8.raw";
  // 2^7 + 1 a side: no diamond leaves the data box.
  const Volume embryo = testing::crop(read_raw(path, *parse_raw_name(path)), {129, 129, 129});
  const Hierarchy memory = Hierarchy::build(embryo);
  const StoreReader store(convert(embryo, "embryo"));
  BrickCache cache(store, kHugeBudget);
  const PagedVolume paged(cache);
  int stood = 0, fell_back = 0;
  // The default's level 18 lies below most of a 129^3 volume's cuts; 12 is where the default sits
  // relative to the cut of a budget of about 1 M at 1024^3.
  for (const BudgetSample sample : {BudgetSample{12, 3}, BudgetSample{12, 4}, BudgetSample{6, 3}}) {
    for (const int64_t budget : {int64_t{5000}, int64_t{15000}, int64_t{40000}}) {
      ExtractOptions o;
      o.iso = 64.5f, o.topology = TopologyMode::none, o.max_triangles = budget;
      const std::string what =
          describe(o) + " sample level " + std::to_string(sample.level) + " one in " + std::to_string(1 << sample.bits);
      ExtractStats s, exact_s, memory_s, one_s;
      const Mesh m = extract_adaptive(paged, o, &s, sample);
      const Mesh exact = extract_adaptive(paged, o, &exact_s, BudgetSample{});
      EXPECT_FALSE(exact_s.budget_sampled) << what;
      EXPECT_TRUE(same_mesh(m, extract_adaptive(memory, o, &memory_s, sample))) << what << ": in memory";
      EXPECT_EQ(memory_s.chosen_eps, s.chosen_eps) << what;
      EXPECT_EQ(memory_s.budget_sampled, s.budget_sampled) << what;
      {
        const tbb::global_control one(tbb::global_control::max_allowed_parallelism, 1);
        EXPECT_TRUE(same_mesh(m, extract_adaptive(paged, o, &one_s, sample))) << what << ": one thread";
      }
      const auto count = static_cast<int64_t>(m.triangles.size());
      EXPECT_LE(count, budget) << what;
      if (!s.budget_sampled) {
        ++fell_back;
        EXPECT_TRUE(same_mesh(m, exact)) << what << ": the fallback is the exact choice";
        EXPECT_EQ(s.chosen_eps, exact_s.chosen_eps) << what;
        EXPECT_EQ(s.next_triangles, exact_s.next_triangles) << what;
        continue;
      }
      ++stood;
      EXPECT_GE(static_cast<double>(count), 0.9 * static_cast<double>(budget)) << what;
      EXPECT_GT(s.chosen_eps, 0) << what;
      // No finer than the exact choice, which is the finest within the budget.
      EXPECT_LE(count, static_cast<int64_t>(exact.triangles.size())) << what;
      ExtractOptions chosen;
      chosen.iso = o.iso, chosen.topology = o.topology, chosen.eps = s.chosen_eps, chosen.eps_ties = s.chosen_eps_ties;
      EXPECT_TRUE(same_mesh(m, extract(paged, chosen)))
          << what << ": plain extraction at chosen eps " << s.chosen_eps << ", eps-ties " << s.chosen_eps_ties;
    }
  }
  // A sample of subtrees the lattice does not have (below its finest level, or above the level of
  // their common ancestors) is the exact search.
  for (const BudgetSample none : {BudgetSample{40, 3}, BudgetSample{2, 3}}) {
    ExtractOptions o;
    o.iso = 64.5f, o.topology = TopologyMode::none, o.max_triangles = 15000;
    ExtractStats s, exact_s;
    EXPECT_TRUE(same_mesh(extract_adaptive(paged, o, &s, none), extract_adaptive(paged, o, &exact_s, BudgetSample{})))
        << "sample level " << none.level;
    EXPECT_FALSE(s.budget_sampled);
    EXPECT_EQ(s.next_triangles, exact_s.next_triangles);
  }
  RecordProperty("stood", stood);
  RecordProperty("fell_back", fell_back);
  EXPECT_GE(stood, 3);      // the finer sample stood on every budget here
  EXPECT_GE(fell_back, 1);  // 48 of the 384 subtrees of level 6 do not make a trustworthy estimate
}

// 5c. A budget asked for again over a source kept open (BudgetMemo) is the
// choice made the first time, taken without the search: the same mesh, byte for byte, and the
// same report, at the cost of the plain extraction at the chosen eps (the cache's lookups, on one
// thread, are that extraction's). A sampled guess that stood and one that fell back are remembered
// alike. Any option that decides the choice asks anew. Through isotope::Source, paged and in
// memory, the second extraction is the remembered one.
TEST_F(PagedExtract, ABudgetAskedForAgainIsTheFirstChoiceWithoutTheSearch) {
  const std::string path = std::string(ISOTOPE_TEST_DATA) + "/embryo_256x256x256_uint8.raw";
  const Volume embryo = testing::crop(read_raw(path, *parse_raw_name(path)), {129, 129, 129});
  const std::string store_path = convert(embryo, "embryo");
  const StoreReader store(store_path);
  BrickCache cache(store, kHugeBudget);
  const PagedVolume paged(cache);
  const tbb::global_control one(tbb::global_control::max_allowed_parallelism, 1);
  auto lookups = [&] { return cache.stats().hits + cache.stats().bricks_read; };
  BudgetMemo memo;
  int stood = 0, fell_back = 0, exact = 0;
  // Level 12 stands, level 6 falls back on some budgets (5b); no sample is the exact search.
  for (const BudgetSample sample : {BudgetSample{12, 3}, BudgetSample{6, 3}, BudgetSample{}}) {
    for (const int64_t budget : {int64_t{5000}, int64_t{15000}, int64_t{40000}}) {
      ExtractOptions o;
      o.iso = 64.5f, o.topology = TopologyMode::none, o.max_triangles = budget;
      const std::string what = describe(o) + " sample level " + std::to_string(sample.level);
      ExtractStats first, again, alone, plain;
      int64_t before = lookups();
      const Mesh m = extract_adaptive(paged, o, &first, sample, &memo);
      const int64_t searched = lookups() - before;
      EXPECT_FALSE(first.budget_remembered) << what;
      before = lookups();
      const Mesh m2 = extract_adaptive(paged, o, &again, sample, &memo);
      const int64_t remembered = lookups() - before;
      EXPECT_TRUE(again.budget_remembered) << what;
      EXPECT_TRUE(same_mesh(m, m2)) << what;
      EXPECT_EQ(again.chosen_eps, first.chosen_eps) << what;
      EXPECT_EQ(again.chosen_eps_ties, first.chosen_eps_ties) << what;
      EXPECT_EQ(again.next_eps, first.next_eps) << what;
      EXPECT_EQ(again.next_eps_ties, first.next_eps_ties) << what;
      EXPECT_EQ(again.next_triangles, first.next_triangles) << what;
      EXPECT_EQ(again.budget_steps, first.budget_steps) << what;
      EXPECT_EQ(again.budget_sampled, first.budget_sampled) << what;
      EXPECT_EQ(again.tets_visited, first.tets_visited) << what;
      // The memo changes nothing the first time.
      EXPECT_TRUE(same_mesh(m, extract_adaptive(paged, o, &alone, sample))) << what;
      EXPECT_EQ(alone.chosen_eps, first.chosen_eps) << what;
      // The second time is the plain extraction at the chosen eps, and no more.
      ExtractOptions chosen;
      chosen.iso = o.iso, chosen.topology = o.topology, chosen.eps = first.chosen_eps;
      chosen.eps_ties = first.chosen_eps_ties;
      before = lookups();
      if (first.chosen_eps > 0) {
        EXPECT_TRUE(same_mesh(m, extract(paged, chosen, &plain))) << what;
        EXPECT_EQ(remembered, lookups() - before) << what;
      }
      EXPECT_LT(remembered, searched) << what;
      ++(sample.exact() ? exact : first.budget_sampled ? stood : fell_back);
    }
  }
  EXPECT_EQ(memo.size(), 9u);
  EXPECT_GE(stood, 1);
  EXPECT_GE(fell_back, 1);
  EXPECT_EQ(exact, 3);
  // Each option that decides the choice asks anew, and is then remembered on its own.
  ExtractOptions base;
  base.iso = 64.5f, base.topology = TopologyMode::none, base.max_triangles = 15000;
  std::vector<ExtractOptions> others(9, base);
  others[0].iso = 70.5f;
  others[1].max_triangles = 15001;
  others[2].error = ErrorIndicator::surplus;
  others[3].topology = TopologyMode::simplify, others[3].auto_delta = true;  // preserve's coarsest is over 15000
  others[4].focus = Focus{{64, 64, 64}, 30};
  others[5].focus = Focus{{64, 64, 64}, 31};
  others[6].topology = TopologyMode::simplify, others[6].delta = 40;         // a delta given, not chosen
  others[7] = others[6], others[7].delta = 41;                               // that alone differs
  others[6].max_triangles = others[7].max_triangles = 40000;                 // the coarsest at delta 40: 23,462
  others[8].topology = TopologyMode::simplify, others[8].auto_delta = true;  // as 3, by another weight
  others[8].weight = SimplificationWeight::gradient;
  for (const ExtractOptions& o : others) {
    ExtractStats s;
    extract_adaptive(paged, o, &s, BudgetSample{}, &memo);
    EXPECT_FALSE(s.budget_remembered) << describe(o);
  }
  EXPECT_EQ(memo.size(), 18u);
  // Through isotope::Source, the store and the array alike.
  const Source from_store = open_volume(VolumeSpec{store_path, std::nullopt, std::nullopt});
  const Source from_array = open_volume(embryo);
  for (const Source* source : {&from_store, &from_array}) {
    ExtractStats s1, s2;
    const Mesh a = source->extract(base, {}, &s1);
    const Mesh b = source->extract(base, {}, &s2);
    EXPECT_FALSE(s1.budget_remembered);
    EXPECT_TRUE(s2.budget_remembered);
    EXPECT_TRUE(same_mesh(a, b));
    EXPECT_TRUE(same_mesh(a, extract_adaptive(paged, base, nullptr, BudgetSample{})));
  }
}

// 6. The cache: when the store fits, each brick is read at most once and no more bytes than the
// store's bricks hold; when it does not, the mesh is the same and the decoded bytes held at once
// stay within what BrickCache guarantees: after each admission the resident bytes are
// within max(budget, that brick), and the peak is taken before eviction, so
// peak <= max(budget, largest brick) + largest brick, budget being the cache's own (its floor
// raises a small one). Bricks evicted but still pinned by a reader are not counted in the peak.
TEST_F(PagedExtract, CacheReadsEachBrickOnceAndStaysNearItsBudget) {
  struct Case {
    std::string name;
    Volume volume;
    float iso;
    int bits;
  };
  const Case cases[] = {
      {"noise", as_raw(testing::crop(generate_noise(50, 13), {49, 45, 39})), 0.0f, 3},
      {"neghip", testing::load_shared(testing::shared_volumes()[1]), 128.5f, 4},
  };
  for (const Case& c : cases) {
    const std::string file = convert(c.volume, c.name, c.bits);
    const StoreReader store(file);
    const DecodedSizes sizes = decoded_sizes(store);
    const int64_t bricks = store.layout().brick_count();
    const uint64_t compressed = store.brick_area_end() - kHeaderBytes;
    ASSERT_LE(compressed, std::filesystem::file_size(file));
    ExtractOptions o;
    o.iso = c.iso;
    o.topology = TopologyMode::none;  // eps 0: every brick near the surface is read
    for (size_t threads : {1, 4}) {
      const tbb::global_control limit(tbb::global_control::max_allowed_parallelism, threads);
      const std::string what = c.name + " threads " + std::to_string(threads);
      BrickCache cache(store, kHugeBudget);
      const PagedVolume paged(cache);
      const Mesh expected = extract(paged, o);
      const BrickCacheStats first = cache.stats();
      EXPECT_GT(first.bricks_read, 0) << what;
      EXPECT_LE(first.bricks_read, bricks) << what;
      EXPECT_LE(first.bytes_read, compressed) << what;
      EXPECT_LE(first.peak_bytes, sizes.total) << what;
      EXPECT_GT(first.hits, 0) << what;
      // Again through the same cache: all hits, nothing read.
      EXPECT_TRUE(same_mesh(expected, extract(paged, o))) << what;
      EXPECT_EQ(cache.stats().bricks_read, first.bricks_read) << what;
      EXPECT_EQ(cache.stats().bytes_read, first.bytes_read) << what;
      for (uint64_t budget : {kTinyBudget, sizes.largest, sizes.total / 8}) {
        const PagedRun r = run_paged(store, budget, o);
        const std::string at = what + " budget " + std::to_string(budget);
        EXPECT_TRUE(same_mesh(expected, r.mesh)) << at;
        EXPECT_LE(r.cache.peak_bytes, std::max(r.budget, sizes.largest) + sizes.largest) << at;
        EXPECT_GE(r.cache.bricks_read, first.bricks_read) << at << ": it needs every brick the big cache read";
        EXPECT_GE(r.cache.bytes_read, first.bytes_read) << at;
      }
    }
  }
}

// The claims of the slabs ahead: each slab is handed out once, beyond the furthest claimed, from
// wherever the first claim starts and up to the last slab of the process's share.
TEST(FinestMarch, SlabClaimsHandOutEachSlabOnceBeyondTheFurthest) {
  using Range = std::pair<int64_t, int64_t>;
  {
    SlabClaims claims;
    EXPECT_EQ(claims.claim(0, 5), Range(1, 6));
    EXPECT_EQ(claims.claim(1, 5), Range(6, 7));
    EXPECT_EQ(claims.claim(2, 5), Range(7, 8));
  }
  {
    SlabClaims claims;  // a later slab first: the earlier one's window is claimed already
    EXPECT_EQ(claims.claim(5, 5), Range(6, 11));
    const Range r = claims.claim(4, 5);
    EXPECT_GE(r.first, r.second) << r.first << " " << r.second;
    EXPECT_EQ(claims.claim(6, 5), Range(11, 12));
  }
  {
    SlabClaims claims;  // a share that starts at slab 7
    EXPECT_EQ(claims.claim(7, 5), Range(8, 13));
    const Range r = claims.claim(8, 4);  // its window ends at the furthest claimed
    EXPECT_GE(r.first, r.second) << r.first << " " << r.second;
  }
  {
    SlabClaims claims;  // a share of slabs 3 to 9: nothing past 9
    claims.end_at(9);
    EXPECT_EQ(claims.claim(3, 5), Range(4, 9));
    EXPECT_EQ(claims.claim(4, 5), Range(9, 10));
    const Range r = claims.claim(5, 5);
    EXPECT_GE(r.first, r.second) << r.first << " " << r.second;
  }
}

// The finest march asks ahead for the bricks it will read: a brick first read by slab r > 0 is
// first asked for by slab max(0, r - finest_slabs_ahead()), nothing is asked for that no slab
// reads (the blocks the range records cull are not asked for), and no block is asked for twice;
// also where hints pay only once a brick was read, so that the first slab asks after its march.
// Over an in-memory hierarchy whose bricks note what they are asked for and what is read of them,
// a slab at a time in order.
struct NotingBricks : hierarchy_internal::MemoryBricks {
  std::vector<int64_t>* asked;
  std::vector<int64_t>* read;
  bool* read_once = nullptr;  // where hints pay once a brick was read; else always
  bool hints_pay() const { return !read_once || *read_once; }
  void prefetch_brick(int64_t index) { asked->push_back(index); }
  const float* values(int64_t index) const {
    read->push_back(index);
    if (read_once) *read_once = true;
    return MemoryBricks::values(index);
  }
};

// The blocks asked for, by their lowest corner, besides their bricks.
struct NotingLookup : CompactLookup<NotingBricks> {
  using CompactLookup<NotingBricks>::CompactLookup;
  std::vector<Coord>* blocks;
  void prefetch_block(const Coord& lo, const std::array<int64_t, 3>& n) {
    blocks->push_back(lo);
    CompactLookup<NotingBricks>::prefetch_block(lo, n);
  }
};

TEST(FinestMarch, AsksForEachBrickTheSlabsAheadOfItsFirstReadAndNoOther) {
  struct Case {
    std::string name;
    Volume volume;
    float iso;
  };
  const Case cases[] = {{"noise", as_raw(testing::crop(generate_noise(70, 5), {69, 61, 67})), 0.1f},
                        {"sphere", as_raw(generate_sphere(65)), 0.0f}};
  // The window counts the threads: two, so that the volumes have slabs beyond it on any machine.
  const tbb::global_control limit(tbb::global_control::max_allowed_parallelism, 2);
  const int64_t ahead = finest_slabs_ahead();
  for (const Case& c : cases)
    for (const int bits : {2, 3, 4})
      for (const bool late : {false, true}) {
        const std::string what = c.name + " bits " + std::to_string(bits) + (late ? ", hints once read" : "");
        const Hierarchy h = Hierarchy::build(c.volume, {}, bits);
        std::vector<int64_t> asked, read;
        std::vector<Coord> asked_blocks;
        bool read_once = false;
        NotingLookup reader(h.layout(), h.indexer(),
                            NotingBricks{{&h, h.layout().brick_nodes()}, &asked, &read, late ? &read_once : nullptr});
        reader.blocks = &asked_blocks;
        ExtractOptions o;
        o.iso = c.iso;
        o.topology = TopologyMode::none;
        const traversal::SplitRule rule(o, h.lattice(), h.origin(), h.spacing(), h.error_fold());
        const SlabPlan plan = finest_plan(h.lattice(), h.data_dims(), o.iso, h.origin(), h.spacing());
        MeshBuilder builder(o.iso, h.lattice().side, h.origin(), h.spacing());
        std::atomic<int64_t> blocks{0}, cells{0};
        SlabClaims claims;
        std::map<int64_t, int64_t> first_asked, first_read;  // brick -> slab
        int64_t slab = 0;
        for (int64_t z0 = 0; z0 < plan.cell_layers; z0 += plan.slab_layers, ++slab) {
          asked.clear(), read.clear();
          march_finest_slab(reader, rule, plan, h.data_dims(), z0, std::min(z0 + plan.slab_layers, plan.cell_layers),
                            builder, blocks, cells, claims);
          for (int64_t b : asked) first_asked.try_emplace(b, slab);
          for (int64_t b : read) first_read.try_emplace(b, slab);
        }
        ASSERT_GT(slab, ahead + 2) << what;
        // Some bricks are never read (the range records cull their blocks), so that "no other" means something.
        EXPECT_LT(static_cast<int64_t>(first_read.size()), h.layout().band(0).brick_count()) << what;
        int64_t checked = 0;
        for (const auto& [b, r] : first_read) {
          if (r == 0) continue;
          const auto a = first_asked.find(b);
          ASSERT_NE(a, first_asked.end())
              << what << ": brick " << b << ", first read by slab " << r << ", never asked for";
          EXPECT_EQ(a->second, std::max<int64_t>(0, r - ahead))
              << what << ": brick " << b << ", first read by slab " << r;
          ++checked;
        }
        EXPECT_GT(checked, 20) << what;
        for (const auto& [b, a] : first_asked)
          EXPECT_TRUE(first_read.count(b)) << what << ": brick " << b << " asked for by slab " << a << ", never read";
        std::set<Coord> once;
        for (const Coord& lo : asked_blocks)
          EXPECT_TRUE(once.insert(lo).second)
              << what << ": block at " << lo[0] << " " << lo[1] << " " << lo[2] << " asked for twice";
        EXPECT_GT(once.size(), 20u) << what;
      }
}

// A process that marches a share of the slabs (among several) asks for nothing past the share's
// last slab, whose next slabs are another process's, and every brick it asks for, it reads.
TEST(FinestMarch, AsksForNothingPastItsShare) {
  const tbb::global_control limit(tbb::global_control::max_allowed_parallelism, 2);
  const Hierarchy h = Hierarchy::build(as_raw(testing::crop(generate_noise(70, 5), {69, 61, 67})), {}, 3);
  std::vector<int64_t> asked, read;
  std::vector<Coord> asked_blocks;
  NotingLookup reader(h.layout(), h.indexer(), NotingBricks{{&h, h.layout().brick_nodes()}, &asked, &read});
  reader.blocks = &asked_blocks;
  ExtractOptions o;
  o.iso = 0.1f;
  o.topology = TopologyMode::none;
  const traversal::SplitRule rule(o, h.lattice(), h.origin(), h.spacing(), h.error_fold());
  const SlabPlan plan = finest_plan(h.lattice(), h.data_dims(), o.iso, h.origin(), h.spacing());
  MeshBuilder builder(o.iso, h.lattice().side, h.origin(), h.spacing());
  std::atomic<int64_t> blocks{0}, cells{0};
  const int64_t side = plan.slab_layers, count = slab_count(plan);
  const int64_t first = 1, last = count - 3;  // the share: slabs [first, last]
  ASSERT_GT(last - first, 2);
  SlabClaims claims;
  claims.end_at(last);
  for (int64_t s = first; s <= last; ++s)
    march_finest_slab(reader, rule, plan, h.data_dims(), s * side, std::min((s + 1) * side, plan.cell_layers), builder,
                      blocks, cells, claims);
  EXPECT_GT(asked_blocks.size(), 20u);
  for (const Coord& lo : asked_blocks) {
    EXPECT_GT(lo[2], first * side) << "a block of the share's first slab, or before it, asked for";
    EXPECT_LE(lo[2], last * side) << "a block past the share asked for";
  }
  const std::set<int64_t> was_read(read.begin(), read.end());
  for (int64_t b : asked) EXPECT_TRUE(was_read.count(b)) << "brick " << b << " asked for, never read";
}

// A store wholly in the page cache is read without a single read-ahead hint (each would be a
// system call for nothing); once reads wait for the disk, an extraction at eps 0 passes hints
// ahead of its march. Each half needs what it says of the page cache, and is skipped, saying so,
// where the file system does not do it.
TEST_F(PagedExtract, ReadHintsOnlyOnceReadsWaitForTheDisk) {
  const std::string file = convert(as_raw(generate_noise(65, 21)), "hints", 3);
  testing::read_into_page_cache(file);
  if (testing::page_cached(file, kHeaderBytes) != 1)
    GTEST_SKIP() << "the file system refuses RWF_NOWAIT, or does not keep " << file << " in the page cache";
  ExtractOptions o;
  o.iso = 0.0f;
  o.topology = TopologyMode::none;
  {
    // Up to three tries, each from the file read whole into the page cache again: under memory
    // pressure the kernel may drop a page of it before the extraction reads it (seen once in
    // CI, by the command's twin of this test). A reader that always waits fails all three.
    std::optional<PagedRun> warm;
    for (int tries = 0; tries < 3; ++tries) {
      if (!testing::read_into_page_cache(file)) continue;
      const StoreReader store(file);
      warm = run_paged(store, kHugeBudget, o);
      if (warm->cache.read_waits == 0) break;
    }
    if (!warm) GTEST_SKIP() << "the page cache did not keep " << file << " whole in three tries";
    EXPECT_GT(warm->cache.bricks_read, 0);
    EXPECT_EQ(warm->cache.read_waits, 0);
    EXPECT_EQ(warm->cache.read_hints, 0);
  }
  ASSERT_TRUE(testing::drop_from_page_cache(file)) << file << ": fdatasync or posix_fadvise failed";
  if (testing::page_cached(file, kHeaderBytes) != 0)
    GTEST_SKIP() << "the page cache keeps " << file << " when asked to drop it (a file system in memory?)";
  const StoreReader store(file);
  const PagedRun cold = run_paged(store, kHugeBudget, o);
  EXPECT_GT(cold.cache.read_waits, 0);
  EXPECT_GT(cold.cache.read_hints, 0);
}

// 7. A brick with one flipped byte: a paged extraction that reads it throws an IoError naming it
// ("brick 12 "), from any thread count and cache budget, never crashes; one that does not read it
// gives the good mesh; the same reader threads extract the good store correctly afterwards.
// Corrupts every `stride`-th brick in turn and extracts with each (threads, cache budget) of
// `schedule`, with and without a triangle budget.
void PagedTest::expect_corrupt_bricks_named(size_t stride, const std::vector<std::pair<size_t, uint64_t>>& schedule) {
  const std::string good = convert(as_raw(testing::crop(generate_noise(40, 21), {21, 17, 19})), "good", 3);
  const testing::Bytes good_bytes = testing::read_bytes(good);
  const std::string bad = path("bad.isotope");
  ExtractOptions o;
  o.topology = TopologyMode::none;
  ExtractOptions budgeted = o;  // the budget search reads bricks on the calling thread first
  Mesh expected, expected_budgeted;
  std::vector<BrickEntry> directory;
  {
    const StoreReader store(good);
    for (int64_t i = 0; i < store.layout().brick_count(); ++i) directory.push_back(store.entry(i));
    expected = run_paged(store, kHugeBudget, o).mesh;
    budgeted.max_triangles = static_cast<int64_t>(expected.triangles.size()) / 2;
    expected_budgeted = run_paged(store, kHugeBudget, budgeted).mesh;
  }
  ASSERT_GT(expected.triangles.size(), 100u);
  std::mt19937 rng(5);
  int named = 0, tried = 0;
  for (size_t i = 0; i < directory.size(); i += stride, ++tried) {
    const BrickEntry& e = directory[i];
    auto bytes = good_bytes;
    bytes[e.offset + rng() % e.bytes[0]] ^= static_cast<uint8_t>(1 + rng() % 255);  // the core, which mode none reads
    testing::write_file(bad, "", bytes);
    const StoreReader store(bad);
    const std::string name = "brick " + std::to_string(i) + " ";
    for (const ExtractOptions* opt : {&o, &budgeted}) {
      int threw = 0, runs = 0;
      for (const auto& [threads, budget] : schedule) {
        const tbb::global_control limit(tbb::global_control::max_allowed_parallelism, threads);
        const std::string what = name + "threads " + std::to_string(threads) + " budget " + std::to_string(budget) +
                                 (opt == &o ? "" : " with a triangle budget");
        ++runs;
        try {
          const Mesh m = run_paged(store, budget, *opt).mesh;
          EXPECT_TRUE(same_mesh(opt == &o ? expected : expected_budgeted, m)) << what << ": not read, so unchanged";
        } catch (const IoError& err) {
          EXPECT_CONTAINS(err.what(), name) << what;
          ++threw;
        }
      }
      // The bricks an extraction reads do not depend on threads or the cache budget.
      EXPECT_TRUE(threw == 0 || threw == runs) << name << "threw in " << threw << " of " << runs << " runs";
      if (opt == &o) named += threw == runs;
    }
  }
  // At eps 0 in mode none every brick a surface passes through is read; coarse bricks always.
  EXPECT_GE(named, tried / 2) << "of " << tried << " bricks";
  const StoreReader store(good);
  for (size_t threads : {1, 4}) {
    const tbb::global_control limit(tbb::global_control::max_allowed_parallelism, threads);
    EXPECT_TRUE(same_mesh(expected, run_paged(store, kTinyBudget, o).mesh)) << "after the errors, threads " << threads;
  }
}

// The cache's bookkeeping for a brick is made when the brick is first asked for, not for every
// brick of the store when the cache opens: a coarse extraction asks for a few thousand of a big
// store's hundreds of thousands (millions at 2048^3), and a slot for each, made up front, was
// 13 MB of memory touched at 1024^3 before the first brick was read.
TEST_F(PagedExtract, CacheMakesSlotsOnlyForTheBricksAskedFor) {
  const StoreReader store(convert(testing::load_shared(testing::shared_volumes()[1]), "neghip", 3));
  const int64_t bricks = store.layout().brick_count();
  BrickCache cache(store, kHugeBudget);
  EXPECT_EQ(cache.stats().slots, 0);
  const PagedVolume paged(cache);
  ExtractOptions o;
  o.iso = 128.5f, o.eps = 64, o.topology = TopologyMode::none;
  EXPECT_FALSE(extract(paged, o).triangles.empty());
  const BrickCacheStats coarse = cache.stats();
  RecordProperty("bricks", std::to_string(bricks));
  RecordProperty("slots after a coarse extraction", std::to_string(coarse.slots));
  EXPECT_GE(coarse.slots, coarse.bricks_read);  // nothing evicted: every brick read has its slot
  EXPECT_LT(coarse.slots, bricks / 2);          // 334 of 893 when written
  // Asking for a brick makes its slot, once.
  int64_t fresh = 0;
  while (fresh < bricks && cache.stats().slots == coarse.slots) cache.get(fresh++);
  EXPECT_EQ(cache.stats().slots, coarse.slots + 1);
  cache.get(fresh - 1);
  EXPECT_EQ(cache.stats().slots, coarse.slots + 1);
  EXPECT_EQ(cache.stats().bricks_read, coarse.bricks_read + 1);
}

// A cache keeps a quarter of its budget while an extraction reads each brick once (one pass in
// traversal order): the rest would be memory filled once and never read again. When the bricks it
// reads are ones it read before (an extraction asked for again), it keeps the whole budget from
// then on, and an extraction asked for again reads nothing. (A budget's search says so beforehand:
// the next test.)
TEST_F(PagedExtract, CacheKeepsAQuarterOfItsBudgetUntilItReadsBricksAgain) {
  const StoreReader store(convert(testing::load_shared(testing::shared_volumes()[1]), "neghip", 3));
  const DecodedSizes sizes = decoded_sizes(store);
  ExtractOptions o;
  o.iso = 128.5f, o.topology = TopologyMode::none;
  const tbb::global_control one(tbb::global_control::max_allowed_parallelism, 1);
  BrickCache cache(store, sizes.total);
  ASSERT_EQ(cache.budget_bytes(), sizes.total);
  const PagedVolume paged(cache);
  const Mesh expected = extract(paged, o);
  const BrickCacheStats first = cache.stats();
  RecordProperty("decoded MB, whole store", std::to_string(sizes.total >> 20));
  RecordProperty("bricks read, first extraction", std::to_string(first.bricks_read));
  EXPECT_EQ(first.working_bytes, sizes.total / 4);
  // Within a quarter, give or take the bricks the reader holds (16) and the one being admitted.
  EXPECT_LE(first.peak_bytes, sizes.total / 4 + 17 * sizes.largest);
  EXPECT_GT(first.bricks_read * static_cast<int64_t>(sizes.largest), static_cast<int64_t>(sizes.total / 2))
      << "the extraction must read more than the quarter holds";
  int64_t read_before = first.bricks_read;
  int asked = 1;
  for (; asked < 4; ++asked) {
    EXPECT_TRUE(same_mesh(expected, extract(paged, o))) << "asked " << asked + 1 << " times";
    const BrickCacheStats now = cache.stats();
    const int64_t read = now.bricks_read - read_before;
    read_before = now.bricks_read;
    RecordProperty("bricks read, asked " + std::to_string(asked + 1) + " times", std::to_string(read));
    if (read == 0) break;
    EXPECT_EQ(now.working_bytes, sizes.total) << "asked " << asked + 1 << " times, read " << read << " bricks";
  }
  EXPECT_LT(asked, 4) << "an extraction asked for again keeps reading bricks";
  EXPECT_LE(cache.stats().peak_bytes, sizes.total + 17 * sizes.largest);
}

// A triangle budget's search reads the bricks its extraction reads next: the cache keeps its whole
// budget from the start of the search, where a fixed eps keeps a quarter (above). The mesh is the
// same either way.
TEST_F(PagedExtract, ABudgetSearchKeepsTheWholeCacheBudgetFromItsStart) {
  const StoreReader store(convert(testing::load_shared(testing::shared_volumes()[1]), "neghip", 3));
  const DecodedSizes sizes = decoded_sizes(store);
  ExtractOptions o;
  o.iso = 128.5f, o.topology = TopologyMode::none, o.max_triangles = 20000;
  const tbb::global_control one(tbb::global_control::max_allowed_parallelism, 1);
  BrickCache cache(store, sizes.total);
  const PagedVolume paged(cache);
  ExtractStats stats;
  const Mesh budgeted = extract(paged, o, &stats);
  const BrickCacheStats after = cache.stats();
  EXPECT_EQ(after.working_bytes, sizes.total);
  // Not because the search found itself reading bricks again: fewer misses than one window.
  EXPECT_LT(after.bricks_read, 512);
  ExtractOptions fixed = o;
  fixed.max_triangles = 0, fixed.eps = stats.chosen_eps, fixed.eps_ties = stats.chosen_eps_ties;
  BrickCache fresh(store, sizes.total);
  EXPECT_TRUE(same_mesh(budgeted, extract(PagedVolume(fresh), fixed)));
  EXPECT_EQ(fresh.stats().working_bytes, sizes.total / 4);
}

// The cache holds a store's values in the bytes its header promises (BrickValues): a uint8 scan
// in one, 8-bit codes in one, 16-bit codes in two, floats in four; and the records' range and
// bound in 32-bit words beside values of one byte, else in 64. Every value and every record word
// of every brick reads back as the very bits the store holds, and a brick takes nodes x (4 + 1)
// or nodes x (8 + width) bytes.
TEST_F(PagedExtract, BrickValuesAreHeldInTheBytesTheStoresTypePromises) {
  struct Case {
    std::string name, raw;
    int quantize_bits, bytes;
  };
  const std::string data = ISOTOPE_TEST_DATA;
  const std::vector<Case> cases = {{"neghip", data + "/neghip_66x66x66_uint8.raw", 0, 1},
                                   {"hydrogen", data + "/hydrogen_64x64x64_float32.raw", 0, 4},
                                   {"hydrogen16", data + "/hydrogen_64x64x64_float32.raw", 16, 2},
                                   {"hydrogen8", data + "/hydrogen_64x64x64_float32.raw", 8, 1}};
  for (const Case& c : cases) {
    ConvertOptions o;
    o.quantize_bits = c.quantize_bits;
    const std::string path = (dir_ / (c.name + ".isotope")).string();
    convert_to_store(*open_box_reader({c.raw, std::nullopt, std::nullopt}, dir_.string()), path, o);
    const StoreReader store(path);
    const StoreLayout& layout = store.layout();
    BrickCache cache(store, kHugeBudget);
    EXPECT_EQ(cache.value_bytes(), c.bytes) << c.name;
    const auto nodes = static_cast<size_t>(layout.brick_nodes());
    std::vector<float> values(nodes);
    std::vector<uint64_t> bounds(nodes);
    const uint64_t bounds_bytes = c.bytes == 1 ? 4 : 8;
    int64_t differ = 0, records_differ = 0, records = 0, wrong_size = 0;
    for (int64_t i = 0; i < layout.brick_count(); ++i) {
      const uint64_t before = cache.stats().peak_bytes;
      const std::shared_ptr<CachedBrick> brick = cache.get(i);
      wrong_size += cache.stats().peak_bytes - before != nodes * (bounds_bytes + static_cast<uint64_t>(c.bytes));
      EXPECT_EQ(brick->narrow(), c.bytes == 1) << c.name;
      store.read_brick(i, {true, false, false, false}, {values.data(), bounds.data()}, values.data());
      for (size_t m = 0; m < nodes; ++m)
        differ += std::bit_cast<uint32_t>(brick->values()[m]) != std::bit_cast<uint32_t>(values[m]);
      if (!stores_records(layout, brick->band())) continue;  // band 0's are computed, on first read
      for (size_t m = 0; m < nodes; ++m, ++records)
        records_differ += (brick->narrow() ? widen_bounds(brick->narrow_bounds()[m]) : brick->bounds()[m]) != bounds[m];
    }
    EXPECT_EQ(differ, 0) << c.name;
    EXPECT_EQ(records_differ, 0) << c.name << ", of " << records;
    EXPECT_GT(records, 0) << c.name;
    EXPECT_EQ(wrong_size, 0) << c.name;
  }
}

// narrow_bounds takes every word a store of one-byte values holds, each reading back as its very
// bits, and refuses every word that no narrow word gives back: at the first and last words, and
// on each side of a block's end, of an array that is not a whole number of its blocks.
TEST(NarrowBounds, TakeEveryRecordOfOneByteValuesExactlyAndNothingElse) {
  constexpr float kInfinity = std::numeric_limits<float>::infinity();
  std::vector<uint64_t> good;
  for (int lo = 0; lo < 256; ++lo)
    for (int hi = lo; hi < 256; ++hi)
      for (const float bound : {0.0f, 0.5f, 765.0f, 14535.0f, 32767.0f, kInfinity})
        good.push_back(bounds_word({bf16_down(static_cast<float>(lo)), bf16_up(static_cast<float>(hi)), bound}));
  for (int halves = 0; halves < 0xffff; ++halves)  // every bound a narrow word holds
    good.push_back(bounds_word({bf16_down(7), bf16_up(200), 0.5f * static_cast<float>(halves)}));
  std::vector<uint32_t> narrow(good.size());
  ASSERT_TRUE(narrow_bounds(good.data(), good.size(), narrow.data()));
  int64_t differ = 0, unset = 0;
  for (size_t i = 0; i < good.size(); ++i)
    differ += widen_bounds(narrow[i]) != good[i], unset += narrow[i] == kUnsetNarrowBounds;
  EXPECT_EQ(differ, 0);
  EXPECT_EQ(unset, 0);

  const auto word = [](uint16_t lo, uint16_t hi, float bound) { return bounds_word({lo, hi, bound}); };
  const uint16_t b3 = bf16_down(3), b9 = bf16_down(9);
  const std::vector<std::pair<const char*, uint64_t>> bad = {
      {"bound -0", word(b3, b9, -0.0f)},
      {"bound NaN", word(b3, b9, std::numeric_limits<float>::quiet_NaN())},
      {"bound -NaN", word(b3, b9, -std::numeric_limits<float>::quiet_NaN())},
      {"bound -inf", word(b3, b9, -kInfinity)},
      {"bound -1", word(b3, b9, -1.0f)},
      {"bound 0.25", word(b3, b9, 0.25f)},
      {"bound 32767.5", word(b3, b9, 32767.5f)},
      {"bound 40000", word(b3, b9, 40000.0f)},
      {"bound a denormal", word(b3, b9, std::numeric_limits<float>::denorm_min())},
      {"lo -0", word(0x8000, b9, 1.0f)},
      {"lo a denormal", word(0x0001, b9, 1.0f)},
      {"lo 0.5", word(bf16_down(0.5f), b9, 1.0f)},
      {"lo -1", word(bf16_down(-1.0f), b9, 1.0f)},
      {"hi 256", word(b3, bf16_up(256.0f), 1.0f)},
      {"hi NaN", word(b3, 0x7fc0, 1.0f)},
      {"hi below lo", word(b9, b3, 1.0f)},
  };
  const uint64_t fine = word(b3, b9, 1.5f);
  for (const auto& [name, w] : bad)
    for (const size_t at : {size_t{0}, size_t{511}, size_t{512}, size_t{999}}) {
      std::vector<uint64_t> words(1000, fine);
      words[at] = w;
      std::vector<uint32_t> out(words.size());
      EXPECT_FALSE(narrow_bounds(words.data(), words.size(), out.data())) << name << " at " << at;
    }
}

// A one-byte store's core section decodes its records straight into narrow words and its values
// into bytes (decode_section's `narrow`): the words narrow_bounds gives of the 64-bit ones and the
// values' bytes, and a refusal where it refuses one, with the corrupt brick's message, wherever the
// record stands; a value that is not a byte's is refused with the message the cache gives it.
TEST(NarrowBounds, ACoreSectionDecodesStraightIntoTheWordsNarrowBoundsGives) {
  const StoreLayout layout({33, 33, 33}, kDefaultBrickBits);
  constexpr int kBand = 1;
  ASSERT_TRUE(stores_records(layout, kBand));
  const auto nodes = static_cast<size_t>(layout.brick_nodes());
  const size_t records = nodes - nodes / 8;
  using Triple = std::array<float, 3>;  // lo, hi, bound
  const auto section = [&](const std::vector<Triple>& r, float value = 7.0f) {
    BrickFields f;
    f.values.assign(nodes, 7.0f);
    f.values[nodes / 2] = value;
    for (auto& field : f.records) field.assign(records, 0.0f);
    for (size_t i = 0; i < records; ++i)
      for (size_t k = 0; k < 3; ++k) f.records[k][i] = r[i % r.size()][k];
    return encode_brick(layout, kBand, f, 3)[static_cast<size_t>(Section::core)];
  };
  // The words both ways; "" when they are taken, else the refusal's message.
  std::vector<float> values(nodes);
  std::vector<uint64_t> wide(nodes);
  std::vector<uint32_t> by_narrow_bounds(nodes), straight(nodes);
  std::vector<uint8_t> value_bytes(nodes);
  constexpr std::string_view kNotAByte = "holds a value that is not a byte's";
  const auto wide_way = [&](const std::vector<uint8_t>& bytes) -> std::string {
    try {
      decode_section(layout, kBand, Section::core, bytes.data(), bytes.size(), {values.data(), wide.data()},
                     values.data(), "brick");
    } catch (const IoError& e) {
      return e.what();
    }
    return narrow_bounds(wide.data(), nodes, by_narrow_bounds.data())
               ? ""
               : std::string("brick: ") + kRecordNotHeld + " (corrupt brick)";
  };
  const auto straight_way = [&](const std::vector<uint8_t>& bytes) -> std::string {
    try {
      const NarrowBrick one_byte{value_bytes.data(), straight.data(), kNotAByte};
      decode_section(layout, kBand, Section::core, bytes.data(), bytes.size(), {}, nullptr, "brick", &one_byte);
    } catch (const IoError& e) {
      return e.what();
    }
    return "";
  };

  constexpr float kInfinity = std::numeric_limits<float>::infinity();
  std::vector<Triple> good;
  for (int lo = 0; lo < 256; lo += 3)
    for (int hi = lo; hi < 256; hi += 5)
      for (const float bound : {0.0f, 0.5f, 765.0f, 14535.0f, 32767.0f, kInfinity})
        good.push_back({static_cast<float>(lo), static_cast<float>(hi), bound});
  for (size_t first = 0; first < good.size(); first += records) {
    const std::vector<Triple> part(good.begin() + static_cast<std::ptrdiff_t>(first),
                                   good.begin() + static_cast<std::ptrdiff_t>(std::min(good.size(), first + records)));
    const std::vector<uint8_t> bytes = section(part);
    ASSERT_EQ(wide_way(bytes), "");
    ASSERT_EQ(straight_way(bytes), "");
    EXPECT_EQ(straight, by_narrow_bounds) << "records from " << first;
    EXPECT_TRUE(std::equal(values.begin(), values.end(), value_bytes.begin())) << "records from " << first;
  }
  for (const float value : {7.5f, 256.0f, -1.0f, -0.0f}) {
    const std::vector<uint8_t> bytes = section({Triple{3, 9, 1.5f}}, value);
    ASSERT_EQ(wide_way(bytes), "");
    EXPECT_EQ(straight_way(bytes), "brick: " + std::string(kNotAByte) + " (corrupt brick)") << value;
  }

  const float nan = std::numeric_limits<float>::quiet_NaN(), denormal = std::numeric_limits<float>::denorm_min();
  const std::vector<std::pair<const char*, Triple>> bad = {
      {"bound -0", {3, 9, -0.0f}},
      {"bound NaN", {3, 9, nan}},
      {"bound -NaN", {3, 9, -nan}},
      {"bound -inf", {3, 9, -kInfinity}},
      {"bound -1", {3, 9, -1}},
      {"bound 0.25", {3, 9, 0.25f}},
      {"bound 32767.5", {3, 9, 32767.5f}},
      {"bound 40000", {3, 9, 40000}},
      {"bound a denormal", {3, 9, denormal}},
      {"lo -0", {-0.0f, 9, 1}},
      {"lo a bfloat16 denormal", {std::bit_cast<float>(0x00010000u), 9, 1}},
      {"lo 0.5", {0.5f, 9, 1}},
      {"lo -1", {-1, 9, 1}},
      {"hi 256", {3, 256, 1}},
      {"hi NaN", {3, nan, 1}},
      {"hi below lo", {9, 3, 1}},
      {"lo not a bfloat16", {3.0001f, 9, 1}},
  };
  for (const auto& [name, triple] : bad)
    for (const size_t at : {size_t{0}, size_t{6}, size_t{7}, records - 1}) {
      std::vector<Triple> r(records, Triple{3, 9, 1.5f});
      r[at] = triple;
      const std::vector<uint8_t> bytes = section(r);
      const std::string refusal = wide_way(bytes);
      EXPECT_NE(refusal, "") << name << " at " << at;
      EXPECT_EQ(straight_way(bytes), refusal) << name << " at " << at;
    }
}

// A narrow word's range and bound, as the traversal reads them straight from it, are the floats of
// the 64-bit word it stands for, bit for bit: every range with some bounds, every bound with some
// ranges, +inf's code included.
TEST(NarrowBounds, RangeAndBoundReadAsTheirWideWordsAre) {
  int64_t compared = 0, differ = 0;
  auto check = [&](uint32_t lo, uint32_t hi, uint32_t halves) {
    const uint32_t w = lo | hi << 8 | halves << 16;
    const DiamondBounds straight = narrow_range_bound(w), wide = range_bound(widen_bounds(w));
    ++compared;
    if (std::memcmp(&straight, &wide, sizeof straight) != 0 && ++differ < 5)
      ADD_FAILURE() << "lo " << lo << " hi " << hi << " halves " << halves << ": " << straight.lo << " " << straight.hi
                    << " " << straight.error_bound << " against " << wide.lo << " " << wide.hi << " "
                    << wide.error_bound;
  };
  for (uint32_t lo = 0; lo < 256; ++lo)
    for (uint32_t hi = lo; hi < 256; ++hi)
      for (const uint32_t halves : {0u, 1u, 2u, 3u, 255u, 1001u, 29070u, 65534u, 0xffffu}) check(lo, hi, halves);
  for (uint32_t halves = 0; halves <= 0xffffu; ++halves)
    for (const auto& [lo, hi] : {std::pair{0u, 0u}, std::pair{7u, 200u}, std::pair{255u, 255u}}) check(lo, hi, halves);
  EXPECT_EQ(differ, 0) << "of " << compared;
  EXPECT_TRUE(std::isinf(narrow_range_bound(0xffff0000u).error_bound));
}

// fewest_bytes gives 1 for integers of 0..255, 2 for those up to 65535, and 4 as soon as one value
// is anything else, wherever it stands: first, last, and within a vectorized loop's steps or its tail.
TEST(FewestBytes, HoldEveryIntegerInItsWidthAndNothingElse) {
  std::vector<float> all(65536);
  for (int k = 0; k < 65536; ++k) all[static_cast<size_t>(k)] = static_cast<float>(k);
  EXPECT_EQ(fewest_bytes(std::span<const float>(all).first(256)), 1);
  EXPECT_EQ(fewest_bytes(all), 2);
  for (int k = 256; k < 65536; ++k) ASSERT_EQ(fewest_bytes(std::vector<float>(3, static_cast<float>(k))), 2) << k;
  constexpr float kInfinity = std::numeric_limits<float>::infinity();
  const std::vector<std::pair<const char*, float>> wide = {
      {"-0", -0.0f},
      {"-1", -1.0f},
      {"-65535", -65535.0f},
      {"0.5", 0.5f},
      {"255.5", 255.5f},
      {"a denormal", std::numeric_limits<float>::denorm_min()},
      {"65536", 65536.0f},
      {"65535.5", 65535.5f},
      {"1e9", 1e9f},
      {"+inf", kInfinity},
      {"-inf", -kInfinity},
      {"NaN", std::numeric_limits<float>::quiet_NaN()},
      {"-NaN", -std::numeric_limits<float>::quiet_NaN()},
  };
  for (const auto& [name, v] : wide)
    for (const size_t at : {size_t{0}, size_t{511}, size_t{512}, size_t{999}}) {
      std::vector<float> values(1000, 7.0f);
      values[at] = v;
      EXPECT_EQ(fewest_bytes(values), 4) << name << " at " << at;
    }
}

// A header that promises integers the bricks do not hold (valid checksums, a lying type or range)
// is named as a corrupt brick by the read that finds it, never narrowed into other values.
TEST_F(PagedExtract, ABrickOutsideItsHeadersTypeIsACorruptBrick) {
  Volume v;
  v.dims = {17, 17, 17};
  v.values.resize(17 * 17 * 17);
  for (size_t i = 0; i < v.values.size(); ++i) v.values[i] = static_cast<float>(i % 97);
  v.values[17 * 17 * 9 + 17 * 4 + 3] = 2.5f;  // node (3, 4, 9)
  const std::string path = convert(v, "lying");
  auto bytes = testing::read_bytes(path);
  StoreHeader h = decode_header(bytes.data(), kHeaderBytes, path);
  ASSERT_EQ(h.source_type, "float32");
  h.source_type = "uint8";
  const auto header = encode_header(h);
  std::copy(header.begin(), header.end(), bytes.begin());
  testing::write_file(path, "", bytes);
  const StoreReader store(path);
  BrickCache cache(store, kHugeBudget);
  ASSERT_EQ(cache.value_bytes(), 1);
  const int64_t band0 = store.layout().brick_index(0, {0, 0, 0});
  std::string message = "no error";
  try {
    cache.get(band0);
  } catch (const IoError& e) {
    message = e.what();
  }
  EXPECT_NE(message.find("(corrupt brick)"), std::string::npos) << message;
  EXPECT_NE(message.find("band 0"), std::string::npos) << message;
  // A brick without the fraction reads (its records too are narrow: the data keep band 1's ranges
  // and bounds integers and halves).
  EXPECT_NO_THROW(cache.get(store.layout().brick_index(1, {0, 0, 0})));
  // verify refuses what the extraction refuses.
  std::string verified = "no error";
  try {
    verify_store(path);
  } catch (const IoError& e) {
    verified = e.what();
  }
  EXPECT_NE(verified.find("band 0"), std::string::npos) << verified;
  EXPECT_NE(verified.find("holds a value that is not an integer of the header's uint8 range"), std::string::npos)
      << verified;
}

// Every brick; every thread count, each with both cache budgets across the bricks' runs.
TEST_F(PagedExtract, CorruptBrickIsNamedFromAnyThreadCount) {
  expect_corrupt_bricks_named(1, {{1, kTinyBudget}, {2, kHugeBudget}, {4, kTinyBudget}, {8, kHugeBudget}});
}

// The same bytes through a uint8 store, whose cache holds 32-bit record words (narrow_bounds),
// band 0's computed on first read by whichever thread gets there: what CI runs under
// ThreadSanitizer for that path.
TEST_F(PagedParallel, SameBytesThroughAUint8Store) {
  const testing::SharedVolume& neghip = testing::shared_volumes()[1];
  ASSERT_EQ(neghip.file, "neghip_66x66x66_uint8.raw");
  const std::string path = (dir_ / "neghip.isotope").string();
  ConvertOptions o;
  o.brick_bits = 3;
  convert_to_store(
      *open_box_reader({std::string(ISOTOPE_TEST_DATA) + "/" + neghip.file, std::nullopt, std::nullopt}, dir_.string()),
      path, o);
  const StoreReader store(path);
  ASSERT_EQ(BrickCache(store, 1).value_bytes(), 1);
  // Under ThreadSanitizer one parallel count holds the races to find (36 s a count there).
#if defined(__SANITIZE_THREAD__)
  const std::vector<size_t> threads = {8};
#else
  const std::vector<size_t> threads = {2, 8};
#endif
  expect_same_bytes("neghip uint8", testing::load_shared(neghip), neghip.isovalues[0], store, threads);
}

// A sample of the bricks on many threads: what CI runs under ThreadSanitizer.
TEST_F(PagedParallel, CorruptBrickIsNamedFromManyThreads) {
  expect_corrupt_bricks_named(5, {{4, kTinyBudget}, {8, kHugeBudget}});
}

}  // namespace
}  // namespace isotope
