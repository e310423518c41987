// Invariant 2 of docs/DESIGN.md: at eps = 0 the adaptive extraction is exactly marching tetrahedra
// over every finest tetrahedron (same triangles), whatever the mode, indicator or dimensions.
// And the baseline itself, built in slabs on several threads, is the one-walk mesh bit for bit, as
// is eps 0 streamed from a file a window of layers at a time.
#include <gtest/gtest.h>
#include <hdf5.h>
#include <linux/perf_event.h>
#include <sys/ioctl.h>
#include <sys/mman.h>
#include <sys/syscall.h>
#include <tbb/global_control.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <bit>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <optional>
#include <random>
#include <span>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include "engine/core/huge_blocks.h"
#include "engine/extract/block_march.h"
#include "engine/extract/column_extremes.h"
#include "engine/extract/extract_drivers.h"
#include "engine/extract/slab_march.h"
#include "engine/extract/streamed_extract.h"
#include "engine/extract/traversal.h"
#include "engine/hierarchy/hierarchy.h"
#include "engine/hierarchy/kuhn.h"
#include "engine/hierarchy/multires_volume.h"
#include "engine/mesh/marching_tetrahedra.h"
#include "engine/synthetic/fields.h"
#include "io/volume/box_reader.h"
#include "io/volume/raw_reader.h"
#include "io/volume/volume_reader.h"
#include "isotope/convert.h"
#include "isotope/error.h"
#include "isotope/source.h"
#include "tests/support/io_error_of.h"
#include "tests/support/temp_dir_test.h"
#include "tests/support/test_support.h"

namespace isotope {
namespace {

using testing::triangle_set;

// Also: the one-shot extraction from the array, which builds no hierarchy at eps 0, gives the
// hierarchy's mesh bit for bit (vertex order included).
void expect_exact_at_eps0(const Volume& volume, float iso, const std::string& what) {
  const auto full = triangle_set(extract_full_resolution(volume, iso));
  const MultiresVolume mv = MultiresVolume::build(volume);
  for (ErrorIndicator err : {ErrorIndicator::bound, ErrorIndicator::surplus})
    for (TopologyMode mode : {TopologyMode::none, TopologyMode::paper, TopologyMode::preserve}) {
      ExtractOptions o;
      o.iso = iso;
      o.error = err;
      o.topology = mode;
      const Mesh m = extract(mv, o);
      const auto adaptive = triangle_set(m);
      ASSERT_EQ(adaptive.size(), full.size())
          << what << " iso " << iso << " " << to_string(err) << " " << to_string(mode);
      EXPECT_TRUE(adaptive == full) << what << " iso " << iso;
      const Mesh one_shot = extract(volume, o);
      EXPECT_TRUE(one_shot.positions == m.positions && one_shot.triangles == m.triangles)
          << what << " iso " << iso << ": the array's mesh differs from the hierarchy's";
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

// At eps 0 cells are marched block by block (extract_finest): blocks of 2, 4 and 8
// cells, cut by the data box on any side, and lattices too small for a block at all.
TEST(ExactAtEpsZero, BlocksOfAnySizeAndBlocksCutByTheDataBox) {
  const Volume noise = generate_noise(21, 5);
  for (const std::array<int64_t, 3>& dims : std::vector<std::array<int64_t, 3>>{
           {2, 2, 2}, {3, 3, 3}, {3, 2, 3}, {5, 4, 3}, {9, 9, 9}, {10, 17, 9}, {21, 13, 18}}) {
    const Volume v = testing::crop(noise, dims);
    for (float iso : {-0.2f, 0.0f, 0.3f})
      expect_exact_at_eps0(
          v, iso, "noise " + std::to_string(dims[0]) + "x" + std::to_string(dims[1]) + "x" + std::to_string(dims[2]));
  }
}

// The block march's memo keeps the low 32 bits of a stamp in each slot and is lent from one
// extraction to the next for the life of the process: its stamps start over before they pass 2^32,
// at a slab's start, and a memo whose stamps ran that far still welds every vertex.
TEST(ExactAtEpsZero, TheEdgeMemoStartsItsStampsOverAndStillWeldsEveryVertex) {
  const Volume v = generate_sphere(33);
  ExtractOptions o;
  o.iso = 0.0f;
  const tbb::global_control one(tbb::global_control::max_allowed_parallelism, 1);
  give_back_slab_memory();
  const Mesh fresh = extract(v, o);
  for (const uint64_t to : {EdgeMemo::kStampLimit - 1, (uint64_t{1} << 32) - 3}) {
    give_back_slab_memory();
    {
      LentEdgeMemo lent;       // the one memo the extraction below takes, slab after slab
      (*lent).reshape(8, 33);  // blocks of 8 cells on a 33-node lattice: it keeps its slots, and stamps
      (*lent).advance_stamp_to(to);
    }
    const Mesh m = extract(v, o);
    EXPECT_EQ(m.positions.size(), fresh.positions.size()) << "stamps from " << to;
    EXPECT_TRUE(m.positions == fresh.positions && m.triangles == fresh.triangles) << "stamps from " << to;
  }
}

// Range culling: a block of 8^3 cells is marched iff the isovalue lies in the range of its nodes
// (min <= iso < max, as the tree's culling), counted here straight from the volume; an
// isovalue above every value marches nothing.
int64_t cells_in_blocks_the_isovalue_cuts(const Volume& v, float iso) {
  const auto& d = v.dims;
  int64_t cells = 0;
  for (int64_t z0 = 0; z0 + 1 < d[2]; z0 += 8)
    for (int64_t y0 = 0; y0 + 1 < d[1]; y0 += 8)
      for (int64_t x0 = 0; x0 + 1 < d[0]; x0 += 8) {
        const int64_t x1 = std::min(x0 + 8, d[0] - 1), y1 = std::min(y0 + 8, d[1] - 1), z1 = std::min(z0 + 8, d[2] - 1);
        float lo = v.at(x0, y0, z0), hi = lo;
        for (int64_t z = z0; z <= z1; ++z)
          for (int64_t y = y0; y <= y1; ++y)
            for (int64_t x = x0; x <= x1; ++x) lo = std::min(lo, v.at(x, y, z)), hi = std::max(hi, v.at(x, y, z));
        if (lo <= iso && iso < hi) cells += (x1 - x0) * (y1 - y0) * (z1 - z0);
      }
  return cells;
}

TEST(ExactAtEpsZero, BlocksTheIsovalueMissesAreNotMarched) {
  const Volume volumes[] = {generate_sphere(65), testing::crop(generate_noise(50, 9), {50, 37, 44})};
  for (const Volume& v : volumes) {
    const MultiresVolume mv = MultiresVolume::build(v);
    ExtractOptions o;
    ExtractStats stats;
    const Mesh m = extract(mv, o, &stats);
    EXPECT_EQ(testing::triangle_set(m), testing::triangle_set(extract_full_resolution(v, 0.0f)));
    const int64_t cut = cells_in_blocks_the_isovalue_cuts(v, 0.0f);
    EXPECT_LT(cut, (v.dims[0] - 1) * (v.dims[1] - 1) * (v.dims[2] - 1)) << "some block is culled";
    EXPECT_EQ(stats.tets_emitted, 6 * cut);
    ExtractStats one_shot;
    extract(v, o, {}, &one_shot);
    EXPECT_EQ(one_shot.tets_emitted, 6 * cut) << "the array's blocks are culled by their own nodes alone";
    o.iso = 1e9f;
    EXPECT_TRUE(extract(mv, o, &stats).triangles.empty());
    EXPECT_EQ(stats.tets_emitted, 0);
    EXPECT_TRUE(extract(v, o, {}, &one_shot).triangles.empty());
    EXPECT_EQ(one_shot.tets_emitted, 0);
  }
}

// The one-shot path builds a hierarchy only when the options need one, and then gives that
// hierarchy's mesh; it refuses what the hierarchy refuses.
TEST(OneShot, EpsAboveZeroOrABudgetGoThroughTheHierarchy) {
  const Volume v = generate_sphere(33);
  const MultiresVolume mv = MultiresVolume::build(v);
  ExtractOptions o;
  EXPECT_FALSE(needs_hierarchy(o));
  o.eps = 0.05;
  EXPECT_TRUE(needs_hierarchy(o));
  Mesh a = extract(v, o), b = extract(mv, o);
  EXPECT_TRUE(a.positions == b.positions && a.triangles == b.triangles);
  EXPECT_LT(a.triangles.size(), extract_full_resolution(v, 0.0f).triangles.size()) << "coarser than eps 0";
  o.eps = 0;
  o.max_triangles = 500;
  EXPECT_TRUE(needs_hierarchy(o));
  a = extract(v, o), b = extract(mv, o);
  EXPECT_TRUE(a.positions == b.positions && a.triangles == b.triangles);
  EXPECT_LE(a.triangles.size(), 500u);
  Volume bad = v;
  bad.values[17] = NAN;
  EXPECT_THROW(extract(bad, ExtractOptions{}), InvalidInput);
  bad.values.pop_back();
  EXPECT_THROW(extract(bad, ExtractOptions{}), InvalidInput);
  ExtractOptions nan_iso;
  nan_iso.iso = NAN;
  EXPECT_THROW(extract(v, nan_iso), OptionError);
}

// eps 0 with tie classes is a cut within the diamonds of error 0 (what a triangle budget may
// choose): through the hierarchy, as the multiresolution volume gives it, with fewer triangles
// than full resolution, which every class refined gives again.
TEST(OneShot, EpsZeroWithTieClassesIsACutNotFullResolution) {
  const testing::SharedVolume& neghip = testing::shared_volumes()[1];  // flat and linear regions
  ASSERT_EQ(neghip.name, "neghip");
  const Volume v = testing::load_shared(neghip);
  const MultiresVolume mv = MultiresVolume::build(v);
  const auto full = extract_full_resolution(v, 64.0f).triangles.size();
  ExtractOptions o;
  o.iso = 64.0f, o.eps = 0, o.eps_ties = 0;
  EXPECT_TRUE(needs_hierarchy(o));
  const Mesh a = extract(v, o), b = extract(mv, o);
  EXPECT_TRUE(a.positions == b.positions && a.triangles == b.triangles);
  EXPECT_LT(a.triangles.size(), full);
  o.eps_ties = kMaxTieClasses;
  EXPECT_EQ(extract(v, o).triangles.size(), full);
}

// The count a triangle budget asks first: the triangles of the full-resolution mesh, from the
// signs of each cell's nodes, equal to the march's on every shared volume (at its isovalues and at
// an integer tie), on synthetic fields cut to odd and thin shapes (every parity of cell), and on
// one and two threads.
TEST(FullResolutionCount, IsTheMarchsTriangleCountOnEveryVolumeIsovalueAndShape) {
  const auto expect_count = [](const Volume& v, float iso, const std::string& what) {
    const auto marched = static_cast<int64_t>(extract_full_resolution(v, iso).triangles.size());
    EXPECT_EQ(count_full_resolution_triangles(v, iso), marched) << what << " iso " << iso;
    const tbb::global_control one(tbb::global_control::max_allowed_parallelism, 1);
    EXPECT_EQ(count_full_resolution_triangles(v, iso), marched) << what << " iso " << iso << ", one thread";
  };
  for (const auto& s : testing::shared_volumes()) {
    const Volume v = testing::load_shared(s);
    for (float iso : s.isovalues) expect_count(v, iso, s.name);
    if (s.name != "hydrogen") expect_count(v, 128.0f, s.name + " integer tie");
  }
  const Volume noise = generate_noise(21, 5);
  for (const std::array<int64_t, 3>& dims : std::vector<std::array<int64_t, 3>>{
           {2, 2, 2}, {3, 2, 3}, {2, 9, 5}, {5, 4, 3}, {10, 17, 9}, {21, 13, 18}, {21, 21, 21}})
    for (float iso : {-0.2f, 0.0f, 0.3f})
      expect_count(testing::crop(noise, dims), iso,
                   "noise " + std::to_string(dims[0]) + "x" + std::to_string(dims[1]) + "x" + std::to_string(dims[2]));
  const Volume sphere = generate_sphere(33);
  EXPECT_GT(count_full_resolution_triangles(sphere, 0.0f), 0);
  EXPECT_EQ(count_full_resolution_triangles(sphere, 10.0f), 0) << "an isovalue above every value";
  EXPECT_EQ(count_full_resolution_triangles(testing::crop(sphere, {33, 33, 1}), 0.0f), 0) << "no cell";
  EXPECT_THROW(count_full_resolution_triangles(sphere, NAN), InvalidInput);
}

// A budget the full-resolution mesh fits takes that mesh without a hierarchy: the same bytes as
// eps 0 and as the search over the hierarchy chooses, from an array and through a Source, which
// then builds none. One triangle less, and the search runs as before.
TEST(FullResolutionCount, ABudgetTheFullMeshFitsTakesItWithoutAHierarchy) {
  const testing::SharedVolume& neghip = testing::shared_volumes()[1];
  ASSERT_EQ(neghip.name, "neghip");
  const Volume v = testing::load_shared(neghip);
  const float iso = neghip.isovalues[0];
  ExtractOptions full;
  full.iso = iso;
  const Mesh reference = extract(v, full);
  const auto triangles = static_cast<int64_t>(reference.triangles.size());
  ASSERT_EQ(count_full_resolution_triangles(v, iso), triangles);
  const MultiresVolume mv = MultiresVolume::build(v);
  for (const int64_t budget : {triangles, triangles + 1, 10 * triangles}) {
    ExtractOptions o = full;
    o.max_triangles = budget;
    EXPECT_TRUE(budget_takes_full_resolution(v, o)) << budget;
    ExtractStats stats;
    const Mesh a = extract(v, o, {}, &stats);
    EXPECT_TRUE(a.positions == reference.positions && a.triangles == reference.triangles) << budget;
    EXPECT_EQ(stats.chosen_eps, 0);
    EXPECT_EQ(stats.chosen_eps_ties, -1);
    EXPECT_EQ(stats.next_triangles, 0) << "nothing finer";
    const Mesh searched = extract(mv, o);
    EXPECT_TRUE(searched.positions == reference.positions && searched.triangles == reference.triangles)
        << budget << ": the search chooses the same mesh";
    const Source source = open_volume(Volume(v));
    source.prepare({o});
    EXPECT_FALSE(source.info().hierarchy_built) << budget << ": prepared";
    const Mesh c = source.extract(o);
    EXPECT_TRUE(c.positions == reference.positions && c.triangles == reference.triangles) << budget;
    EXPECT_FALSE(source.info().hierarchy_built) << budget;
  }
  ExtractOptions o = full;
  o.max_triangles = triangles - 1;
  EXPECT_FALSE(budget_takes_full_resolution(v, o));
  const Source source = open_volume(Volume(v));
  source.prepare({o});
  EXPECT_TRUE(source.info().hierarchy_built) << "prepared for the search";
  const Mesh below = source.extract(o);
  EXPECT_LT(below.triangles.size(), reference.triangles.size());
  EXPECT_TRUE(source.info().hierarchy_built);
  const Mesh searched = extract(mv, o);
  EXPECT_TRUE(below.positions == searched.positions && below.triangles == searched.triangles);
  o.max_triangles = 10 * triangles;
  o.iso = NAN;
  EXPECT_THROW(budget_takes_full_resolution(v, o), OptionError) << "refused as extract refuses it";
  EXPECT_THROW(source.prepare({o}), OptionError);
  EXPECT_THROW(source.extract(o), OptionError);
}

// The blocks are marched in slabs on all threads; the mesh is the same bit for bit.
TEST(ExactAtEpsZero, AnyThreadCountGivesTheSameMeshBitForBit) {
  const MultiresVolume mv = MultiresVolume::build(generate_algebraic(65));
  ExtractOptions o;
  const Mesh reference = [&] {
    const tbb::global_control one(tbb::global_control::max_allowed_parallelism, 1);
    return extract(mv, o);
  }();
  ASSERT_GT(reference.triangles.size(), 0u);
  for (size_t threads : {2, 3, 8}) {
    const tbb::global_control limit(tbb::global_control::max_allowed_parallelism, threads);
    const Mesh m = extract(mv, o);
    EXPECT_TRUE(m.positions == reference.positions) << threads << " threads";
    EXPECT_TRUE(m.triangles == reference.triangles) << threads << " threads";
  }
}

TEST(ExactAtEpsZero, MeshIsWeldedOneVertexPerCutGridEdge) {
  const Mesh m = extract_full_resolution(generate_sphere(33), 0.0f);
  const MeshTopology t = measure_topology(m);
  EXPECT_EQ(t.vertices, static_cast<int64_t>(m.positions.size()));
  EXPECT_EQ(t.euler_characteristic, 2);
  EXPECT_EQ(t.components, 1);
}

// The definition the slabs must reproduce: one welding builder fed every cell, z slowest. welds:
// a welding table lent to the builder, or null for its own.
Mesh one_walk(const Volume& volume, float iso, EdgeVertexMap* welds = nullptr) {
  const auto& d = volume.dims;
  MeshBuilder builder(iso, std::max({d[0], d[1], d[2]}), volume.origin, volume.spacing, welds);
  for (int64_t z = 0; z + 1 < d[2]; ++z)
    for (int64_t y = 0; y + 1 < d[1]; ++y)
      for (int64_t x = 0; x + 1 < d[0]; ++x)
        for (const Tet& t : cell_tetrahedra({x, y, z})) {
          std::array<float, 4> f;
          for (int i = 0; i < 4; ++i) f[i] = volume.at(t[i][0], t[i][1], t[i][2]);
          int64_t e[3][3];
          for (int i = 0; i < 3; ++i)
            for (int a = 0; a < 3; ++a) e[i][a] = t[i + 1][a] - t[0][a];
          const int64_t det = e[0][0] * (e[1][1] * e[2][2] - e[1][2] * e[2][1]) -
                              e[0][1] * (e[1][0] * e[2][2] - e[1][2] * e[2][0]) +
                              e[0][2] * (e[1][0] * e[2][1] - e[1][1] * e[2][0]);
          builder.add_tet(t, f, det > 0);
        }
  return builder.take();
}

// A welding table lent from mesh to mesh (as the traversal lends one from piece to piece) is
// emptied when lent: one that welded this very mesh before, every edge of it taken, welds it
// again as a table of the builder's own does, a small mesh after a large one too. The first
// mesh, part of the next one, leaves stale slots of the same edges (other vertex numbers) in a
// table the next one outgrows: its growth must drop them.
TEST(ExactAtEpsZero, ALentWeldingTableIsEmptiedForEachMesh) {
  const Volume v = generate_sphere(33), part = testing::crop(v, {13, 33, 33});
  const Mesh own_part = one_walk(part, 0.0f), own = one_walk(v, 0.0f);
  ASSERT_GT(own_part.positions.size(), own.positions.size() / 8);
  ASSERT_LT(own_part.positions.size(), own.positions.size() / 2);  // so the table grows for the next
  // and the whole mesh, started on the table's first slots again, outgrows them (half of 4096).
  ASSERT_GT(own.positions.size(), 2048u);
  EdgeVertexMap lent(16);
  const Mesh first = one_walk(part, 0.0f, &lent);
  EXPECT_TRUE(first.positions == own_part.positions && first.triangles == own_part.triangles);
  // Grown by the first whole mesh; each later one starts on the table's first slots again, and a
  // whole mesh grows over the memory the first one left, stale slots and all.
  for (int mesh = 0; mesh < 4; ++mesh) {
    const bool whole = mesh % 2 == 0;
    const Mesh m = one_walk(whole ? v : part, 0.0f, &lent);
    EXPECT_TRUE(m.positions == (whole ? own : own_part).positions) << "mesh " << mesh;
    EXPECT_TRUE(m.triangles == (whole ? own : own_part).triangles) << "mesh " << mesh;
  }
}

int64_t slab_count(const Volume& v) {
  return (v.dims[2] - 1 + full_resolution_slab_layers(v.dims) - 1) / full_resolution_slab_layers(v.dims);
}

// The one-walk mesh, and extract_full_resolution() on 1, 2, 3 and 8 threads, equal bit for bit.
void expect_same_mesh_on_any_threads(const Volume& volume, float iso, const std::string& what) {
  const Mesh reference = one_walk(volume, iso);
  ASSERT_GT(reference.triangles.size(), 0u) << what;
  for (size_t threads : {1, 2, 3, 8}) {
    const tbb::global_control limit(tbb::global_control::max_allowed_parallelism, threads);
    const Mesh m = extract_full_resolution(volume, iso);
    ASSERT_EQ(m.positions.size(), reference.positions.size()) << what << ", " << threads << " threads";
    EXPECT_TRUE(m.positions == reference.positions) << what << ", " << threads << " threads";
    EXPECT_TRUE(m.triangles == reference.triangles) << what << ", " << threads << " threads";
  }
}

TEST(FullResolutionSlabs, SlabsDependOnDimensionsOnlyAndSmallVolumesAreOne) {
  EXPECT_EQ(slab_count(generate_algebraic(65)), 1) << "nothing to merge for a 64^3-cell volume";
  EXPECT_GT(slab_count(generate_algebraic(129)), 1);
  for (size_t threads : {1, 8}) {
    const tbb::global_control limit(tbb::global_control::max_allowed_parallelism, threads);
    EXPECT_EQ(full_resolution_slab_layers({257, 257, 257}), 4) << "a 2^18-cell grain";
    EXPECT_EQ(full_resolution_slab_layers({2, 2, 2}), 1 << 18);
  }
}

TEST(FullResolutionSlabs, AnyThreadCountGivesTheOneWalkMeshBitForBit) {
  const Volume algebraic = generate_algebraic(129);
  ASSERT_GT(slab_count(algebraic), 1) << "the merge must be exercised";
  expect_same_mesh_on_any_threads(algebraic, 0.0f, "algebraic 129");
  expect_same_mesh_on_any_threads(generate_algebraic(65), 0.0f, "algebraic 65, one slab");
  // Odd, non-cubic, several slabs of which the last is short; then one that is a single slab.
  const Volume noise = testing::crop(generate_noise(97, 11), {97, 90, 75});
  ASSERT_GT(slab_count(noise), 1);
  for (float iso : {-0.3f, 0.2f}) expect_same_mesh_on_any_threads(noise, iso, "noise 97x90x75");
  expect_same_mesh_on_any_threads(testing::crop(generate_noise(70, 4), {37, 70, 23}), 0.0f, "noise 37x70x23");
}

// Page faults taken by this thread's own accesses while F runs (the faults of MADV_POPULATE_WRITE
// are the kernel's, not counted here, unlike getrusage's), or -1 where the kernel refuses to say.
template <class F>
int64_t page_faults_of(const F& f) {
  perf_event_attr attr{};
  attr.size = sizeof attr;
  attr.type = PERF_TYPE_SOFTWARE;
  attr.config = PERF_COUNT_SW_PAGE_FAULTS;
  attr.disabled = 1;
  attr.exclude_kernel = 1;
  const int fd = static_cast<int>(::syscall(SYS_perf_event_open, &attr, 0, -1, -1, 0));
  if (fd < 0) {
    f();
    return -1;
  }
  ::ioctl(fd, PERF_EVENT_IOC_ENABLE, 0);
  f();
  ::ioctl(fd, PERF_EVENT_IOC_DISABLE, 0);
  int64_t count = -1;
  if (::read(fd, &count, sizeof count) != sizeof count) count = -1;
  ::close(fd);
  return count;
}

// The mesh's room is faulted in a slab's stretch at a time before the slab is copied there, in
// one call (a page faulted in by its first write costs about twice its share of such a call,
// docs/METHOD.md "Fresh memory"): the extraction's own accesses fault in few of the mesh's pages.
TEST(FullResolutionSlabs, TheMeshIsFaultedInBeforeTheSlabsAreCopiedThere) {
#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
  GTEST_SKIP() << "a sanitizer's writes fault in its own shadow memory";
#else
  // What the count can tell here: fresh pages written one by one take a fault each (not where the
  // kernel maps a huge page at a fault, transparent huge pages `always`).
  constexpr size_t kProbeBytes = size_t{8} << 20;
  void* probe = ::mmap(nullptr, kProbeBytes, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
  ASSERT_NE(probe, MAP_FAILED);
  const int64_t probe_faults = page_faults_of([&] {
    for (size_t at = 0; at < kProbeBytes; at += 4096) static_cast<volatile char*>(probe)[at] = 1;
  });
  ::munmap(probe, kProbeBytes);
  if (probe_faults < 0) GTEST_SKIP() << "perf_event_open refused (kernel.perf_event_paranoid)";
  if (probe_faults < static_cast<int64_t>(kProbeBytes / 4096 / 2))
    GTEST_SKIP() << "fresh pages took " << probe_faults << " faults for " << kProbeBytes / 4096
                 << " pages (huge pages?)";
  const Volume noise = generate_noise(193, 7);
  ASSERT_GT(slab_count(noise), 4);
  const tbb::global_control one(tbb::global_control::max_allowed_parallelism, 1);  // all on this thread
  // Fresh memory, as in a process's first extraction: none kept by the extractions before.
  give_back_slab_memory();
  detail::give_back_huge_blocks(0);
  Mesh m;
  const int64_t faults = page_faults_of([&] { m = extract_full_resolution(noise, 0.0f); });
  const auto pages = static_cast<int64_t>(
      (m.positions.size() * sizeof(m.positions[0]) + m.triangles.size() * sizeof(m.triangles[0])) / 4096);
  ASSERT_GT(pages, 2000);
  EXPECT_LT(faults, pages / 3) << "of " << pages << " pages";  // by the copies: more than PAGES
#endif
}

// Each slab is joined as soon as the slabs before it are, into room reserved as address space for
// the most the plan's cells can make; where that is more than may be reserved (here: layers 2^18
// nodes on a side, over 2^45 bytes; a `ulimit -v` does the same), the slabs are all marched, then
// joined. Both give the one-walk mesh, in arrays of its size, on any number of threads; the room
// reserved while the slabs are marched tells which ran.
TEST(FullResolutionSlabs, WithoutTheAddressSpaceToReserveTheSlabsAreJoinedAfterTheMarch) {
  const Volume v = generate_algebraic(129);
  const Mesh reference = one_walk(v, 0.0f);
  SlabPlan plan;
  plan.cell_layers = v.dims[2] - 1;
  plan.slab_layers = 8;
  plan.side = 129;  // one_walk's, so the same edge keys
  plan.origin = v.origin;
  plan.spacing = v.spacing;
  for (const int64_t layer_side : {int64_t{129}, int64_t{1} << 18})
    for (size_t threads : {1, 2, 3}) {
      SCOPED_TRACE(::testing::Message() << "layers " << layer_side << " nodes on a side, " << threads << " threads");
      const tbb::global_control limit(tbb::global_control::max_allowed_parallelism, threads);
      plan.layer_nodes = {layer_side, layer_side};
      std::atomic<size_t> reserved{0};
      Mesh m = march_in_slabs(plan, [&](int64_t z0, int64_t z1, MeshBuilder& builder) {
        reserved = std::max(reserved.load(), detail::reserved_huge_block_bytes());
        for (int64_t z = z0; z < z1; ++z)
          for (int64_t y = 0; y + 1 < v.dims[1]; ++y)
            for (int64_t x = 0; x + 1 < v.dims[0]; ++x)
              for (const Tet& t : cell_tetrahedra({x, y, z})) {
                std::array<float, 4> f;
                for (int i = 0; i < 4; ++i) f[i] = v.at(t[i][0], t[i][1], t[i][2]);
                builder.add_tet(t, f, traversal::orientation(t) > 0);
              }
      });
      EXPECT_EQ(reserved > 0, layer_side == 129) << "reserved while marching: " << reserved;
      ASSERT_EQ(m.positions.size(), reference.positions.size());
      EXPECT_TRUE(m.positions == reference.positions);
      EXPECT_TRUE(m.triangles == reference.triangles);
      EXPECT_EQ(m.triangles.capacity(), m.triangles.size());
      EXPECT_EQ(m.positions.capacity(), m.positions.size());
      // Joined as marched, the mesh's arrays are the reservations themselves (their huge pages),
      // not copies of them; an array under a huge page is malloc's, a copy.
      const auto adopted = [](size_t bytes) {
        return bytes < detail::kHugePage ? 0 : (bytes + detail::kHugePage - 1) / detail::kHugePage * detail::kHugePage;
      };
      ASSERT_GE(m.triangles.size() * sizeof(m.triangles[0]), detail::kHugePage);
      EXPECT_EQ(detail::reserved_huge_block_bytes(), layer_side == 129
                                                         ? adopted(m.positions.size() * sizeof(m.positions[0])) +
                                                               adopted(m.triangles.size() * sizeof(m.triangles[0]))
                                                         : 0u);
      m = Mesh{};
      EXPECT_EQ(detail::reserved_huge_block_bytes(), 0u) << "the mesh's arrays, once freed, hold no reservation";
    }
}

// An extraction leaves its slabs' builders and arrays, and its mesh's pages once the mesh is
// freed, to the next one in the process (docs/METHOD.md, "eps = 0 by blocks"): one after an
// extraction of another grid, isovalue, origin and spacing gives the one-walk mesh all the same.
TEST(FullResolutionSlabs, AnExtractionAfterOneOfAnotherGridGivesTheOneWalkMesh) {
  const Volume algebraic = generate_algebraic(129);
  Volume noise = testing::crop(generate_noise(97, 11), {97, 90, 75});
  noise.origin = {1.5, -2.0, 3.0};
  noise.spacing = {0.5, 2.0, 1.25};
  const Mesh algebraic_reference = one_walk(algebraic, 0.0f), noise_reference = one_walk(noise, 0.2f);
  const tbb::global_control limit(tbb::global_control::max_allowed_parallelism, 2);
  // While a mesh lives, the kept pages are those of its arrays' reservations that were copied into
  // arrays under a huge page (malloc's) and freed: every kept block was taken by its arrays.
  const auto copied = [](const Mesh& m) {
    return detail::kHugePage * ((m.positions.size() * sizeof(m.positions[0]) < detail::kHugePage ? 1u : 0u) +
                                (m.triangles.size() * sizeof(m.triangles[0]) < detail::kHugePage ? 1u : 0u));
  };
  detail::give_back_huge_blocks(0);
  for (int round = 0; round < 3; ++round) {
    SCOPED_TRACE(::testing::Message() << "round " << round);
    {
      const Mesh m = extract_full_resolution(algebraic, 0.0f);
      EXPECT_TRUE(m.positions == algebraic_reference.positions);
      EXPECT_TRUE(m.triangles == algebraic_reference.triangles);
      EXPECT_EQ(detail::warm_reservation_bytes(), copied(m)) << "the last mesh's pages taken by this one's arrays";
    }
    EXPECT_GE(detail::warm_reservation_bytes(), algebraic_reference.triangles.size() * 12)
        << "the freed mesh's pages kept for the next";
    {
      const Mesh m = extract_full_resolution(noise, 0.2f);
      EXPECT_TRUE(m.positions == noise_reference.positions);
      EXPECT_TRUE(m.triangles == noise_reference.triangles);
      EXPECT_EQ(detail::warm_reservation_bytes(), copied(m));
    }
  }
}

TEST(FullResolutionSlabs, RealVolumeWithAOneLayerLastSlabGivesTheOneWalkMesh) {
  const testing::SharedVolume& bolt = testing::shared_volumes()[3];
  const Volume v = testing::load_shared(bolt);
  ASSERT_EQ(slab_count(v), 3);
  ASSERT_EQ((v.dims[2] - 1) % full_resolution_slab_layers(v.dims), 1) << "the last slab is one layer";
  for (float iso : bolt.isovalues) expect_same_mesh_on_any_threads(v, iso, bolt.name);
}

TEST(FullResolutionSlabs, VolumeTwoNodesThickGivesTheOneWalkMesh) {
  const Volume v = testing::make_volume({400, 300, 2}, [](int64_t x, int64_t y, int64_t z) {
    return std::sin(0.05 * static_cast<double>(x)) * std::cos(0.07 * static_cast<double>(y)) +
           0.3 * static_cast<double>(z) - 0.1;
  });
  expect_same_mesh_on_any_threads(v, 0.0f, "400x300x2");
}

// Surfaces in and next to the plane two slabs share: ties at the isovalue on it, and a layer of
// alternating signs in it, which cuts the in-plane edges each slab welds on its own.
TEST(FullResolutionSlabs, SurfaceInTheSharedPlaneGivesTheOneWalkMesh) {
  const std::array<int64_t, 3> dims{65, 48, 129};
  const int64_t z0 = full_resolution_slab_layers(dims);
  ASSERT_LT(z0, dims[2] - 1);
  const Volume ramp =
      testing::make_volume(dims, [&](int64_t, int64_t, int64_t z) { return static_cast<double>(z - z0); });
  for (float iso : {0.0f, -0.5f, 0.5f}) expect_same_mesh_on_any_threads(ramp, iso, "ramp z - z0");
  const Volume holes = testing::make_volume(
      dims, [&](int64_t x, int64_t y, int64_t z) { return z == z0 && (x + 2 * y) % 3 != 0 ? -1.0 : 1.0; });
  expect_same_mesh_on_any_threads(holes, 0.0f, "plane of holes");
  const Volume ties = testing::make_volume(dims, [&](int64_t x, int64_t y, int64_t z) {
    return z == z0 ? ((x * 7 + y * 3) % 5 == 0 ? 1.0 : 0.0) : std::abs(z - z0) == 1 ? -1.0 : 0.5;
  });
  expect_same_mesh_on_any_threads(ties, 0.0f, "ties in the plane");
}

// The column pass that culls blocks (ArrayReader::block_cut), as the processor runs it (AVX2 where
// it has it) and as the baseline x86-64 runs it: the same extremes bit for bit, and the same NaN
// found, over rows of every width up to a few vectors, with NaN, infinities and signed zeros.
template <class T>
void expect_fold_agrees(std::mt19937& random, const std::vector<T>& pool, bool find_nan, const std::string& what) {
  for (size_t width = 1; width < 80; ++width)
    for (int round = 0; round < 4; ++round) {
      std::vector<T> row(width), low(width), high(width);
      for (size_t x = 0; x < width; ++x) {
        row[x] = pool[random() % pool.size()];
        low[x] = pool[random() % pool.size()];
        high[x] = pool[random() % pool.size()];
      }
      std::vector<T> low2 = low, high2 = high;
      // What the pass is: each column's least and greatest so far, as these comparisons fold them
      // (a NaN in the row is never taken, one already in LOW or HIGH stays).
      std::vector<T> want_low(width), want_high(width);
      for (size_t x = 0; x < width; ++x) {
        want_low[x] = row[x] < low[x] ? row[x] : low[x];
        want_high[x] = row[x] > high[x] ? row[x] : high[x];
      }
      const bool nan = fold_row_extremes(row.data(), width, low.data(), high.data(), find_nan);
      const bool nan2 = fold_row_extremes_baseline(row.data(), width, low2.data(), high2.data(), find_nan);
      EXPECT_EQ(nan, nan2) << what << ", width " << width;
      EXPECT_EQ(std::memcmp(low.data(), low2.data(), width * sizeof(T)), 0) << what << ", width " << width;
      EXPECT_EQ(std::memcmp(high.data(), high2.data(), width * sizeof(T)), 0) << what << ", width " << width;
      bool any_nan = false;
      for (const T v : row) any_nan = any_nan || v != v;
      EXPECT_EQ(nan, find_nan && any_nan) << what << ", width " << width;
      EXPECT_EQ(std::memcmp(low.data(), want_low.data(), width * sizeof(T)), 0) << what << ", width " << width;
      EXPECT_EQ(std::memcmp(high.data(), want_high.data(), width * sizeof(T)), 0) << what << ", width " << width;
    }
}

TEST(ColumnExtremes, TheProcessorsPassAndTheBaselinesAgree) {
#if defined(__x86_64__) && defined(__GNUC__)
  // Without AVX2 both run the baseline's code, and the comparison would prove nothing.
  if (!__builtin_cpu_supports("avx2")) GTEST_SKIP() << "this processor has no AVX2";
#endif
  std::mt19937 random(7);
  const float inf = std::numeric_limits<float>::infinity();
  const std::vector<float> floats{0.0f, -0.0f, 1.5f, -2.25f, 3e38f, -3e38f, inf, -inf, std::nanf(""), 7.0f, 64.5f};
  expect_fold_agrees(random, floats, true, "float, finding NaN");
  expect_fold_agrees(random, floats, false, "float");
  expect_fold_agrees<uint8_t>(random, {0, 1, 127, 128, 200, 255}, false, "uint8");
  expect_fold_agrees<uint16_t>(random, {0, 1, 32767, 32768, 40000, 65535}, false, "uint16");
  expect_fold_agrees<int16_t>(random, {-32768, -1, 0, 1, 255, 32767}, false, "int16");
}

// eps = 0 from a volume streamed a window of z-layers at a time (docs/METHOD.md, "eps = 0 from a file"):
// the array's mesh bit for bit, each layer read once in order (the top layer of a window again as
// the first of the next), whatever the threads.
// UNCHECKED: the source also reads without the check that values are finite, which the march
// then makes.
struct RecordedLayers {
  const Volume& volume;
  std::vector<std::array<int64_t, 2>> reads;  // (first layer, layers) per call
  LayerSource source(bool unchecked = false) {
    const std::function<void(int64_t, int64_t, float*)> read = [this](int64_t z, int64_t count, float* out) {
      reads.push_back({z, count});
      std::copy(volume.data() + volume.index(0, 0, z), volume.data() + volume.index(0, 0, z + count), out);
    };
    return {volume.dims, volume.spacing, volume.origin, read, unchecked ? read : nullptr};
  }
};

// A field whose planes (312 KB) make a window one layer of blocks: five windows, the last 7 cell
// layers thick; small, for the sanitizers, which run the streamed march's reader and windows.
Volume five_windows() {
  return testing::make_volume({300, 260, 40}, [](int64_t x, int64_t y, int64_t z) {
    return std::sin(0.05 * static_cast<double>(x)) + std::cos(0.07 * static_cast<double>(y)) +
           0.1 * static_cast<double>(z % 13);
  });
}

void expect_streamed_is_the_arrays_mesh(const Volume& volume, float iso, const std::string& what,
                                        int64_t min_windows = 1) {
  ExtractOptions o;
  o.iso = iso;
  const Mesh reference = extract(volume, o);
  ASSERT_GT(reference.triangles.size(), 0u) << what;
  // Read unchecked on one thread and on two (one process's way), checked on one (a process group's).
  for (const auto& [threads, unchecked] : {std::pair{1, true}, {2, true}, {1, false}}) {
    const tbb::global_control limit(tbb::global_control::max_allowed_parallelism, static_cast<size_t>(threads));
    RecordedLayers layers{volume, {}};
    ExtractStats stats;
    const Mesh m = extract_streamed(layers.source(unchecked), o, &stats);
    EXPECT_TRUE(m.positions == reference.positions && m.triangles == reference.triangles)
        << what << " iso " << iso << ", " << threads << " threads" << (unchecked ? ", read unchecked" : "");
    EXPECT_GT(stats.tets_emitted, 0) << what;
    ASSERT_GE(static_cast<int64_t>(layers.reads.size()), min_windows) << what;
    int64_t next = 0;
    for (const auto& [z, count] : layers.reads) {
      EXPECT_EQ(z, next) << what << ": layers read out of order or twice";
      EXPECT_GE(count, 2) << what;
      next = z + count - 1;
    }
    EXPECT_EQ(next, volume.dims[2] - 1) << what << ": not every layer read";
  }
}

TEST(Streamed, EveryLayerReadOnceInOrderAndTheMeshIsTheArraysBitForBit) {
  for (const auto& s : testing::shared_volumes()) {
    const Volume v = testing::load_shared(s);
    for (float iso : s.isovalues) expect_streamed_is_the_arrays_mesh(v, iso, s.name);
  }
  const Volume wide = five_windows();
  expect_streamed_is_the_arrays_mesh(wide, 0.5f, "wide 300x260x40", 5);
  EXPECT_EQ(streamed_window_bytes(wide.dims), 300 * 260 * 9 * 4);
  EXPECT_EQ(streamed_window_bytes({700, 650, 40}), 700 * 650 * 9 * 4) << "planes of 1.8 MB: still one layer of blocks";
  expect_streamed_is_the_arrays_mesh(generate_noise(9, 3), 0.0f, "noise 9");  // one window, one slab
  expect_streamed_is_the_arrays_mesh(generate_noise(5, 3), 0.0f, "noise 5");  // blocks of 4 cells
  EXPECT_EQ(streamed_window_bytes({9, 9, 9}), 9 * 9 * 9 * 4) << "a window holds no more than the volume";
}

// The real volume the speed targets name, in 16 MB windows of its 64 MB array. Its own test, so that
// the race-checking build, which runs the windows of the test above, can leave its 2.5 M triangles out.
TEST(Streamed, EmbryoInWindowsIsTheArraysMeshBitForBit) {
  const std::string embryo = std::string(ISOTOPE_TEST_DATA) + "/embryo_256x256x256_uint8.raw";
  const Volume e = read_raw(embryo, *parse_raw_name(embryo));
  expect_streamed_is_the_arrays_mesh(e, 64.5f, "embryo", 4);
}

// Integers streamed as the file stores them (LayerSource::read_stored), converted in the blocks
// marched only: the array's mesh bit for bit, on one thread and on two, each layer read once in
// order, none read as floats. VOLUME's values are integers in T's range.
template <class T>
void expect_stored_is_the_arrays_mesh(const Volume& volume, ScalarType type, float iso, const std::string& what) {
  ExtractOptions o;
  o.iso = iso;
  const Mesh reference = extract(volume, o);
  ASSERT_GT(reference.triangles.size(), 0u) << what;
  const std::vector<T> stored(volume.values.begin(), volume.values.end());
  const auto layer = static_cast<size_t>(volume.dims[0] * volume.dims[1]);
  for (int threads : {1, 2}) {
    const tbb::global_control limit(tbb::global_control::max_allowed_parallelism, static_cast<size_t>(threads));
    int64_t next = 0;
    bool in_order = true;
    LayerSource source{volume.dims, volume.spacing, volume.origin,
                       [&](int64_t, int64_t, float*) { ADD_FAILURE() << what << ": read as floats"; }, nullptr};
    source.stored = type;
    source.read_stored = [&](int64_t z, int64_t count, unsigned char* out) {
      in_order = in_order && z == next;
      next = z + count - 1;
      std::memcpy(out, stored.data() + static_cast<size_t>(z) * layer, static_cast<size_t>(count) * layer * sizeof(T));
    };
    const Mesh m = extract_streamed(source, o);
    EXPECT_TRUE(m.positions == reference.positions && m.triangles == reference.triangles)
        << what << ", " << threads << " threads";
    EXPECT_TRUE(in_order) << what << ": layers read out of order or twice";
    EXPECT_EQ(next, volume.dims[2] - 1) << what << ": not every layer read";
  }
}

// VOLUME with each value v as a * v + b.
Volume scaled(Volume volume, float a, float b) {
  for (float& v : volume.values) v = a * v + b;
  return volume;
}

TEST(Streamed, IntegersAreMarchedAsTheFileStoresThem) {
  for (const auto& s : testing::shared_volumes()) {
    const Volume v = testing::load_shared(s);
    if (!std::ranges::all_of(v.values, [](float x) { return x >= 0 && x <= 255 && x == std::floor(x); })) continue;
    for (float iso : s.isovalues) {
      expect_stored_is_the_arrays_mesh<uint8_t>(v, ScalarType::uint8, iso, s.name + " as uint8");
      // Above 32767 as uint16, below 0 as int16: every value a distinct float.
      expect_stored_is_the_arrays_mesh<uint16_t>(scaled(v, 250, 7), ScalarType::uint16, iso * 250 + 7,
                                                 s.name + " as uint16");
      expect_stored_is_the_arrays_mesh<int16_t>(scaled(v, 250, -32000), ScalarType::int16, iso * 250 - 32000,
                                                s.name + " as int16");
    }
  }
  // The types' extremes side by side, every cell cut.
  const Volume checker = testing::make_volume(
      {19, 17, 18}, [](int64_t x, int64_t y, int64_t z) { return static_cast<double>((x + y + z) % 2); });
  expect_stored_is_the_arrays_mesh<uint16_t>(scaled(checker, 65535, 0), ScalarType::uint16, 65534.5f, "0 and 65535");
  expect_stored_is_the_arrays_mesh<int16_t>(scaled(checker, 65535, -32768), ScalarType::int16, -32767.5f,
                                            "-32768 and 32767");
}

TEST(Streamed, AFailedReadStopsTheExtractionWithItsError) {
  const std::string embryo = std::string(ISOTOPE_TEST_DATA) + "/embryo_256x256x256_uint8.raw";
  const Volume e = read_raw(embryo, *parse_raw_name(embryo));
  ExtractOptions o;
  o.iso = 64.5f;
  for (int64_t bad : {int64_t{0}, int64_t{100}, int64_t{255}})
    for (int threads : {1, 2}) {
      const tbb::global_control limit(tbb::global_control::max_allowed_parallelism, static_cast<size_t>(threads));
      RecordedLayers layers{e, {}};
      LayerSource source = layers.source();
      const auto read = source.read_layers;
      source.read_layers = [&](int64_t z, int64_t count, float* out) {
        if (z <= bad && bad < z + count) throw IoError("layer " + std::to_string(bad) + " unreadable");
        read(z, count, out);
      };
      try {
        extract_streamed(source, o);
        ADD_FAILURE() << "a failed read at layer " << bad << " went unnoticed";
      } catch (const IoError& error) {
        EXPECT_EQ(std::string(error.what()), "layer " + std::to_string(bad) + " unreadable");
      }
    }
}

// Read unchecked, a value that is not finite anywhere (a corner, a face, a block's edge, a
// window's last layer) is found by the march, and named in the words a checked read gives, the
// first in the file when there are several, whatever slab met one first, also beside a failed
// read; read errors still stop it.
TEST(Streamed, AValueNotFiniteReadUncheckedIsNamedAsACheckedReadNamesIt) {
  const Volume wide = five_windows();
  ASSERT_EQ(streamed_window_bytes(wide.dims), 300 * 260 * 9 * 4);
  ExtractOptions o;
  o.iso = 0.5f;
  const float nan = std::numeric_limits<float>::quiet_NaN(), inf = std::numeric_limits<float>::infinity();
  using Bad = std::vector<std::pair<std::array<int64_t, 3>, float>>;
  for (const Bad& bad :
       {Bad{{{0, 0, 0}, nan}}, Bad{{{299, 259, 39}, inf}}, Bad{{{299, 0, 17}, -inf}}, Bad{{{150, 8, 8}, nan}},
        Bad{{{3, 200, 8}, nan}, {{250, 2, 36}, inf}}, Bad{{{10, 10, 35}, nan}, {{5, 5, 2}, -inf}}}) {
    Volume v = wide;
    for (const auto& [at, value] : bad) v.values[v.index(at[0], at[1], at[2])] = value;
    const auto checked = [&](int64_t z, int64_t count, float* out) {
      std::copy(v.data() + v.index(0, 0, z), v.data() + v.index(0, 0, z + count), out);
      check_finite(out, {0, 0, z}, {v.dims[0], v.dims[1], count}, "layers");
    };
    const auto unchecked = [&](int64_t z, int64_t count, float* out) {
      std::copy(v.data() + v.index(0, 0, z), v.data() + v.index(0, 0, z + count), out);
    };
    const std::string expected = testing::io_error_of([&] { check_finite(v, "layers"); });
    ASSERT_TRUE(testing::contains_text(expected, "is not finite"));
    for (int threads : {1, 2}) {
      const tbb::global_control limit(tbb::global_control::max_allowed_parallelism, static_cast<size_t>(threads));
      const LayerSource source{v.dims, v.spacing, v.origin, checked, unchecked};
      EXPECT_EQ(testing::io_error_of([&] { extract_streamed(source, o); }), expected) << threads << " threads";
    }
  }
  // Not finite when read unchecked, finite when read again: the file changed meanwhile.
  Volume changed = wide;
  changed.values[changed.index(100, 100, 20)] = nan;
  const LayerSource source{
      wide.dims, wide.spacing, wide.origin,
      [&](int64_t z, int64_t count, float* out) {
        std::copy(wide.data() + wide.index(0, 0, z), wide.data() + wide.index(0, 0, z + count), out);
      },
      [&](int64_t z, int64_t count, float* out) {
        std::copy(changed.data() + changed.index(0, 0, z), changed.data() + changed.index(0, 0, z + count), out);
      }};
  EXPECT_CONTAINS(testing::io_error_of([&] { extract_streamed(source, o); }), "changed meanwhile");
  // A value that is not finite and a failed read in another window: the first in the file is
  // named, as a checked read names it, whichever the reader or a worker met first.
  // Windows here are one slab, 8 cell layers: the value lies in the last rows of the first window
  // while the reader fails the second, or the other way round, or three windows apart.
  for (const auto& [nan_layer, unreadable] : {std::pair<int64_t, int64_t>{5, 10}, {3, 30}, {12, 3}, {30, 3}}) {
    Volume v = wide;
    v.values[v.index(250, 255, nan_layer)] = nan;
    const auto fails = [&, unreadable](int64_t z, int64_t count) {
      if (z <= unreadable && unreadable < z + count)
        throw IoError("layer " + std::to_string(unreadable) + " unreadable");
    };
    const std::function<void(int64_t, int64_t, float*)> checked = [&](int64_t z, int64_t count, float* out) {
      fails(z, count);
      std::copy(v.data() + v.index(0, 0, z), v.data() + v.index(0, 0, z + count), out);
      check_finite(out, {0, 0, z}, {v.dims[0], v.dims[1], count}, "layers");
    };
    const std::function<void(int64_t, int64_t, float*)> unchecked = [&](int64_t z, int64_t count, float* out) {
      fails(z, count);
      std::copy(v.data() + v.index(0, 0, z), v.data() + v.index(0, 0, z + count), out);
    };
    const std::string expected = testing::io_error_of([&] {
      extract_streamed(LayerSource{v.dims, v.spacing, v.origin, checked, nullptr}, o);
    });
    EXPECT_CONTAINS(expected, nan_layer < unreadable ? "is not finite" : "unreadable");
    for (int threads : {1, 2}) {
      const tbb::global_control limit(tbb::global_control::max_allowed_parallelism, static_cast<size_t>(threads));
      EXPECT_EQ(testing::io_error_of([&] {
                  extract_streamed(LayerSource{v.dims, v.spacing, v.origin, checked, unchecked}, o);
                }),
                expected)
          << threads << " threads, value at layer " << nan_layer << ", read failing at " << unreadable;
    }
  }
  // A failed unchecked read stops the extraction with its error.
  RecordedLayers layers{wide, {}};
  LayerSource failing = layers.source(true);
  failing.read_unchecked = [](int64_t z, int64_t, float*) {
    throw IoError("layer " + std::to_string(z) + " unreadable");
  };
  EXPECT_EQ(testing::io_error_of([&] { extract_streamed(failing, o); }), "layer 0 unreadable");
}

TEST(Streamed, CancelledWhileItReadsItStops) {
  const std::string embryo = std::string(ISOTOPE_TEST_DATA) + "/embryo_256x256x256_uint8.raw";
  const Volume e = read_raw(embryo, *parse_raw_name(embryo));
  for (int threads : {1, 2}) {
    const tbb::global_control limit(tbb::global_control::max_allowed_parallelism, static_cast<size_t>(threads));
    std::atomic<bool> cancel{false};
    ExtractCall o;
    o.iso = 64.5f;
    o.cancel = &cancel;
    RecordedLayers layers{e, {}};
    LayerSource source = layers.source();
    const auto read = source.read_layers;
    source.read_layers = [&](int64_t z, int64_t count, float* out) {
      if (z > 0) cancel = true;
      read(z, count, out);
    };
    EXPECT_THROW(extract_streamed(source, o), ExtractionCancelled) << threads << " threads";
  }
}

TEST(Streamed, OnlyFullResolutionIsStreamed) {
  const Volume v = generate_sphere(33);
  RecordedLayers layers{v, {}};
  ExtractOptions o;
  EXPECT_TRUE(streamed_extract_applies(v.dims, o));
  EXPECT_FALSE(streamed_extract_applies({2, 2, 2}, o)) << "no block fits";
  o.eps = 0.5;
  EXPECT_FALSE(streamed_extract_applies(v.dims, o));
  EXPECT_THROW(extract_streamed(layers.source(), o), std::logic_error);
  o.eps = 0;
  o.max_triangles = 100;
  EXPECT_FALSE(streamed_extract_applies(v.dims, o));
  o.max_triangles = 0;
  o.eps_ties = 0;
  EXPECT_FALSE(streamed_extract_applies(v.dims, o));
  EXPECT_TRUE(layers.reads.empty());
}

bool same_mesh(const Mesh& a, const Mesh& b) { return a.positions == b.positions && a.triangles == b.triangles; }

// A Source opened on a volume file streams it at eps 0, every time, and reads
// it whole once for the first extraction that needs its hierarchy. A file cut short after the open
// shows which: a streamed extraction fails, one from the volume held in memory does not.
class SourceOfAFile : public testing::TempDirTest {
 protected:
  std::string copy_of(const std::string& name) {
    const std::string to = path(name);
    std::filesystem::copy_file(std::string(ISOTOPE_TEST_DATA) + "/" + name, to);
    return to;
  }
  // An extraction at eps 0 and a coarse one, with their meshes from the volume in memory.
  struct FineAndCoarse {
    ExtractOptions fine, coarse;
    Mesh fine_mesh, coarse_mesh;
  };
  static FineAndCoarse fine_and_coarse(const Volume& v, float iso, double coarse_eps) {
    FineAndCoarse r;
    r.fine.iso = r.coarse.iso = iso;
    r.coarse.eps = coarse_eps;
    r.fine_mesh = extract(v, r.fine);
    r.coarse_mesh = extract(v, r.coarse);
    return r;
  }
  // A coarse extraction in MODE (simplify with DELTA).
  static ExtractOptions coarse_in(TopologyMode mode, float iso, double eps, double delta = 0) {
    ExtractOptions o;
    o.iso = iso;
    o.eps = eps;
    o.topology = mode;
    if (mode == TopologyMode::simplify) o.delta = delta;
    return o;
  }
  // Four extractions from SOURCE at once, each on a thread of its own, alternately A and B (B
  // first with B_FIRST): how many gave their mesh. What one throws fails the test.
  static int right_at_once(const Source& source, const ExtractOptions& a, const Mesh& a_mesh, const ExtractOptions& b,
                           const Mesh& b_mesh, bool b_first = false) {
    std::atomic<int> right{0};
    std::vector<std::thread> threads;
    for (int t = 0; t < 4; ++t)
      threads.emplace_back([&, t] {
        const bool is_b = (t + (b_first ? 1 : 0)) % 2 == 1;
        try {
          if (same_mesh(source.extract(is_b ? b : a), is_b ? b_mesh : a_mesh)) ++right;
        } catch (const std::exception& e) {
          ADD_FAILURE() << e.what();
        }
      });
    for (std::thread& t : threads) t.join();
    return right;
  }
  // The file RAW converted into a kept store, opened: what the store a Source makes of it must give.
  Source converted(const std::string& raw) {
    const std::string store = path("kept.isotope");
    convert({raw, std::nullopt, std::nullopt}, store);
    return open_volume({store, std::nullopt, std::nullopt});
  }
};

VolumeSpec spec_of(const std::string& file) { return {file, std::nullopt, std::nullopt}; }

TEST_F(SourceOfAFile, EpsZeroStreamsTheFileEveryTimeAndAHierarchyIsAStoreOfItsOwn) {
  const std::string raw = copy_of("bolt_70x123x66_uint8.raw");
  const auto [fine, coarse, fine_mesh, coarse_mesh] = fine_and_coarse(read_volume(spec_of(raw)), 64.5f, 1);
  {
    const Source source = open_volume(spec_of(raw));
    EXPECT_FALSE(source.info().hierarchy_built);
    EXPECT_EQ(source.info().dims, (std::array<int64_t, 3>{70, 123, 66}));
    EXPECT_TRUE(same_mesh(source.extract(fine), fine_mesh));
    EXPECT_TRUE(same_mesh(source.extract(fine), fine_mesh)) << "streamed again";
    EXPECT_FALSE(source.info().values_in_memory);
    std::filesystem::resize_file(raw, 70 * 123 * 60);  // layers 60.. gone
    EXPECT_CONTAINS(testing::io_error_of([&] { source.extract(fine); }), raw);
    EXPECT_CONTAINS(testing::io_error_of([&] { source.extract(coarse); }), raw);
  }
  std::filesystem::remove(raw);
  copy_of("bolt_70x123x66_uint8.raw");
  const Source source = open_volume(spec_of(raw));
  EXPECT_TRUE(same_mesh(source.extract(coarse), coarse_mesh));  // converts the volume into a store
  EXPECT_TRUE(source.info().hierarchy_built);
  EXPECT_FALSE(source.info().values_in_memory);
  std::filesystem::resize_file(raw, 0);
  EXPECT_TRUE(same_mesh(source.extract(coarse), coarse_mesh)) << "from its store";
  EXPECT_CONTAINS(testing::io_error_of([&] { source.extract(fine); }), raw) << "eps 0 streams the file still";
}

// The hierarchy of a volume file, or of an array, is a store convert writes into the temporary
// directory and unlinks at once: every extraction from it gives the mesh of the hierarchy in
// memory, in every topology mode and for either error, the critical points are the store's, and
// nothing is left in that directory while the source lives, nor after.
TEST_F(SourceOfAFile, AHierarchyIsAStoreInTheTemporaryDirectoryThatLeavesNothingThere) {
  const std::string raw = copy_of("bolt_70x123x66_uint8.raw");
  const Volume v = read_volume(spec_of(raw));
  const std::string scratch = path("scratch");
  std::filesystem::create_directory(scratch);
  const testing::TemporaryDirectoryIs tmp(scratch);
  const std::string store = path("bolt.isotope");
  convert(spec_of(raw), store);
  const Source converted = open_volume(spec_of(store));
  const Hierarchy in_memory = Hierarchy::build(v);
  for (const bool from_array : {false, true}) {
    const Source source = from_array ? open_volume(Volume(v)) : open_volume(spec_of(raw));
    for (const TopologyMode mode :
         {TopologyMode::none, TopologyMode::paper, TopologyMode::preserve, TopologyMode::simplify})
      for (const ErrorIndicator error : {ErrorIndicator::bound, ErrorIndicator::surplus}) {
        ExtractOptions o;
        o.iso = 64.5f;
        o.eps = 2;
        o.topology = mode;
        o.error = error;
        if (mode == TopologyMode::simplify) o.delta = 20;
        const Mesh m = source.extract(o);
        EXPECT_GT(m.triangles.size(), 100u);
        EXPECT_TRUE(same_mesh(m, extract(in_memory, o))) << to_string(mode) << " " << from_array;
        EXPECT_TRUE(same_mesh(m, converted.extract(o))) << to_string(mode) << " " << from_array;
        EXPECT_TRUE(std::filesystem::is_empty(scratch)) << "unlinked once opened";
      }
    const SourceInfo info = source.info();
    EXPECT_TRUE(info.hierarchy_built);
    EXPECT_FALSE(info.store);
    EXPECT_GT(info.store_bytes, 0u) << "the hierarchy's own store";
    EXPECT_EQ(info.cache_mb, 512);
    EXPECT_GT(info.bricks_read, 0);
    EXPECT_EQ(info.values_in_memory, from_array);
    EXPECT_EQ(info.critical_exact, converted.info().critical_exact);
    EXPECT_EQ(info.critical_paper, converted.info().critical_paper);
    for (int t = 0; t < 3; ++t) EXPECT_EQ(info.critical_exact[t], in_memory.stats().critical_exact[t]);
    EXPECT_GT(info.critical_exact[0] + info.critical_exact[1] + info.critical_exact[2], 0);
  }
  EXPECT_TRUE(std::filesystem::is_empty(scratch));
}

// A volume's hierarchy store holds the sections its first extraction reads alone (StoreSections):
// for mode none the records' core, their topology neither computed nor counted; for preserve the
// exact intervals too, the critical points counted, without the simplification weights and the
// paper's intervals; for the surplus error the extra section. Each gives the mesh of a kept store. The first extraction
// that reads a section the store lacks has the volume converted again with every section, to the kept store's bytes and
// critical points, and that store serves every mode after it. So from a file and from an array.
TEST_F(SourceOfAFile, AVolumesStoreHoldsTheSectionsItsFirstExtractionReadsThenEveryOne) {
  const std::string raw = copy_of("bolt_70x123x66_uint8.raw");
  const std::string scratch = path("scratch");
  std::filesystem::create_directory(scratch);
  const testing::TemporaryDirectoryIs tmp(scratch);
  const Source kept_store = converted(raw);
  const SourceInfo kept = kept_store.info();
  const ExtractOptions none = coarse_in(TopologyMode::none, 64.5f, 2),
                       preserve = coarse_in(TopologyMode::preserve, 64.5f, 2),
                       simplify = coarse_in(TopologyMode::simplify, 64.5f, 2, 20);
  ExtractOptions surplus = none;
  surplus.error = ErrorIndicator::surplus;
  uint64_t core_bytes = 0;
  for (const bool from_array : {false, true})
    for (const ExtractOptions& first : {none, preserve, surplus}) {
      const bool counted = first.topology != TopologyMode::none || first.error == ErrorIndicator::surplus;
      const Source source = from_array ? open_volume(read_volume(spec_of(raw))) : open_volume(spec_of(raw));
      EXPECT_TRUE(same_mesh(source.extract(first), kept_store.extract(first))) << from_array;
      const SourceInfo some = source.info();
      EXPECT_TRUE(some.hierarchy_built);
      EXPECT_EQ(some.critical_counted, counted);
      if (counted) {
        EXPECT_EQ(some.critical_exact, kept.critical_exact);
        EXPECT_EQ(some.critical_paper, kept.critical_paper);
        EXPECT_GT(some.store_bytes, core_bytes) << "another section too";
      } else {
        core_bytes = some.store_bytes;
      }
      EXPECT_GT(some.store_bytes, 0u);
      EXPECT_LT(some.store_bytes, kept.store_bytes * (counted ? 9 : 3) / (counted ? 10 : 4));
      EXPECT_TRUE(same_mesh(source.extract(simplify), kept_store.extract(simplify))) << from_array;
      const SourceInfo all = source.info();
      EXPECT_TRUE(all.critical_counted);
      EXPECT_EQ(all.store_bytes, kept.store_bytes);
      EXPECT_EQ(all.critical_exact, kept.critical_exact);
      EXPECT_EQ(all.critical_paper, kept.critical_paper);
      EXPECT_GT(all.preprocess_seconds, some.preprocess_seconds);
      for (const ExtractOptions& o : {none, preserve})
        EXPECT_TRUE(same_mesh(source.extract(o), kept_store.extract(o))) << from_array;
      EXPECT_EQ(source.info().store_bytes, kept.store_bytes) << "the store of every section, kept";
      EXPECT_EQ(source.info().preprocess_seconds, all.preprocess_seconds);
      EXPECT_TRUE(std::filesystem::is_empty(scratch));
    }
}

// Where the volume's second store, of every section, cannot be written (the temporary directory
// gone meanwhile), the hierarchy is built in memory for that extraction and every one after it:
// the store of some sections made before serves none of them, not even those it could.
TEST_F(SourceOfAFile, WithoutRoomForItsSecondStoreAHierarchyIsBuiltInMemory) {
  const std::string raw = copy_of("bolt_70x123x66_uint8.raw");
  const std::string scratch = path("scratch");
  std::filesystem::create_directory(scratch);
  const Source kept_store = converted(raw);
  const ExtractOptions none = coarse_in(TopologyMode::none, 64.5f, 2),
                       simplify = coarse_in(TopologyMode::simplify, 64.5f, 2, 20);
  const Source source = open_volume(spec_of(raw));
  {
    const testing::TemporaryDirectoryIs tmp(scratch);
    EXPECT_TRUE(same_mesh(source.extract(none), kept_store.extract(none)));
  }
  EXPECT_GT(source.info().store_bytes, 0u);
  const testing::TemporaryDirectoryIs gone(path("missing"));
  for (const ExtractOptions& o : {simplify, simplify, none})
    EXPECT_TRUE(same_mesh(source.extract(o), kept_store.extract(o))) << to_string(o.topology);
  EXPECT_TRUE(source.info().values_in_memory);
  EXPECT_EQ(source.info().store_bytes, 0u) << "no store serves it now";
  EXPECT_TRUE(source.info().critical_counted);
  EXPECT_TRUE(std::filesystem::is_empty(scratch));
}

// A hierarchy's store lives as long as its source and is never made durable: its pages go
// through the page cache and are dropped unwritten when the source ends (the convert of the same
// volume to a store that is kept, whose scratch hand-overs are dropped alike, drops a store's size
// less). Where the file system does not count what it drops, skipped, saying so.
TEST_F(SourceOfAFile, AHierarchysStoreIsNeverWrittenToTheDisk) {
  const std::string raw = copy_of("bolt_70x123x66_uint8.raw");
  const testing::FolderOnDisk folder("hierarchy_store");
  const std::string scratch = folder.path() + "/scratch";
  std::filesystem::create_directory(scratch);
  const testing::TemporaryDirectoryIs tmp(scratch);
  std::vector<char> plain(size_t{4} << 20, 'x');
  const int64_t plain_from = testing::cancelled_write_bytes();
  std::ofstream(folder.path() + "/plain.bin", std::ios::binary)
      .write(plain.data(), static_cast<std::streamsize>(plain.size()));
  std::filesystem::remove(folder.path() + "/plain.bin");
  if (plain_from < 0 || testing::cancelled_write_bytes() - plain_from < static_cast<int64_t>(plain.size() / 2))
    GTEST_SKIP() << "the file system of " << scratch << " does not count the unwritten pages it drops";
  const int64_t kept_from = testing::cancelled_write_bytes();
  convert(spec_of(raw), folder.path() + "/kept.isotope");
  std::filesystem::remove(folder.path() + "/kept.isotope");
  const int64_t kept_dropped = testing::cancelled_write_bytes() - kept_from;
  uint64_t store_bytes = 0;
  const int64_t source_from = testing::cancelled_write_bytes();
  {
    const Source source = open_volume(spec_of(raw));
    ExtractOptions o;
    o.iso = 64.5f;
    o.eps = 2;
    EXPECT_GT(source.extract(o).triangles.size(), 100u);
    store_bytes = source.info().store_bytes;
  }
  const int64_t source_dropped = testing::cancelled_write_bytes() - source_from;
  ASSERT_GT(store_bytes, 0u);
  // Half at least: a writeback that the kernel starts meanwhile may take some of the pages.
  EXPECT_GE(source_dropped - kept_dropped, static_cast<int64_t>(store_bytes / 2))
      << "dropped " << source_dropped << " bytes against " << kept_dropped << " for a kept store of " << store_bytes;
  EXPECT_TRUE(std::filesystem::is_empty(scratch));
}

// Where the temporary directory cannot take the store (missing; refusing files, as /proc does even
// to root; a file size limit the store's writes meet), and for a volume so thin that a store's
// bricks would be mostly padding, the hierarchy is built in memory, to the same mesh, and nothing
// is left behind.
TEST_F(SourceOfAFile, WithoutARoomForItsStoreAHierarchyIsBuiltInMemory) {
  const std::string raw = copy_of("bolt_70x123x66_uint8.raw");
  const auto [fine, coarse, fine_mesh, coarse_mesh] = fine_and_coarse(read_volume(spec_of(raw)), 64.5f, 1);
  for (const std::string& dir : {path("missing"), std::string("/proc")}) {
    const testing::TemporaryDirectoryIs tmp(dir);
    const Source source = open_volume(spec_of(raw));
    EXPECT_TRUE(same_mesh(source.extract(coarse), coarse_mesh)) << dir;
    EXPECT_TRUE(source.info().hierarchy_built) << dir;
    EXPECT_TRUE(source.info().values_in_memory) << dir << ": read whole for the hierarchy in memory";
    EXPECT_EQ(source.info().store_bytes, 0u) << dir;
  }
  const std::string scratch = path("scratch");
  std::filesystem::create_directory(scratch);
  const testing::TemporaryDirectoryIs tmp(scratch);
  {
    const Source source = open_volume(spec_of(raw));
    std::optional<testing::FileSizeLimit> limit(std::in_place, 64 << 10);  // writes past 64 KB fail
    const Mesh m = source.extract(coarse);
    limit.reset();
    EXPECT_TRUE(same_mesh(m, coarse_mesh));
    EXPECT_TRUE(source.info().values_in_memory);
    EXPECT_TRUE(std::filesystem::is_empty(scratch));
  }
  std::vector<float> thin(40000 * 2 * 2);
  for (size_t i = 0; i < thin.size(); ++i) thin[i] = std::sin(static_cast<float>(i % 40000) / 30);
  const std::string thin_raw = path("thin_40000x2x2_float32.raw");
  std::ofstream(thin_raw, std::ios::binary)
      .write(reinterpret_cast<const char*>(thin.data()), static_cast<std::streamsize>(thin.size() * 4));
  ExtractOptions o;
  o.iso = 0.5f;
  o.eps = 0.01;
  const Source source = open_volume(spec_of(thin_raw));
  EXPECT_TRUE(same_mesh(source.extract(o), extract(read_volume(spec_of(thin_raw)), o)));
  EXPECT_TRUE(source.info().values_in_memory);
  EXPECT_TRUE(std::filesystem::is_empty(scratch));
}

// What stops the store's build (a progress callback that throws, as a host's cancel does) stops
// the extraction, with nothing left behind; it is not taken for a lack of room and built again in
// memory.
TEST_F(SourceOfAFile, WhatStopsAHierarchysStoreStopsTheExtraction) {
  const std::string raw = copy_of("bolt_70x123x66_uint8.raw");
  const std::string scratch = path("scratch");
  std::filesystem::create_directory(scratch);
  const testing::TemporaryDirectoryIs tmp(scratch);
  std::atomic<int> calls{0};
  RunContext run;
  run.progress = [&](double) {
    if (calls++ == 0) throw IoError("stopped by the host");
  };
  const Source source = open_volume(spec_of(raw));
  ExtractOptions o;
  o.iso = 64.5f;
  o.eps = 1;
  EXPECT_EQ(testing::io_error_of([&] { source.extract(o, run); }), "stopped by the host");
  EXPECT_TRUE(std::filesystem::is_empty(scratch));
  EXPECT_FALSE(source.info().values_in_memory) << "the volume was not read whole after it";
  EXPECT_GT(source.extract(o).triangles.size(), 1000u) << "built on the next extraction";
  EXPECT_GT(source.info().store_bytes, 0u);
  EXPECT_TRUE(std::filesystem::is_empty(scratch));
}

// Extractions from one Source on several threads at once (as Source promises): some stream the file
// while others build the hierarchy's store, once, and page it; each gets its own mesh. Run under
// ThreadSanitizer in CI.
TEST_F(SourceOfAFile, ExtractionsOnSeveralThreadsAtOnceEachGetTheirMesh) {
  const std::string raw = copy_of("neghip_66x66x66_uint8.raw");
  const auto [fine, coarse, fine_mesh, coarse_mesh] = fine_and_coarse(read_volume(spec_of(raw)), 128.5f, 4);
  for (int round = 0; round < 3; ++round) {
    const Source source = open_volume(spec_of(raw));
    EXPECT_EQ(right_at_once(source, fine, fine_mesh, coarse, coarse_mesh), 4) << "round " << round;
    EXPECT_FALSE(source.info().values_in_memory);
    EXPECT_TRUE(source.info().hierarchy_built);
    EXPECT_TRUE(same_mesh(source.extract(fine), fine_mesh)) << "streamed again";
  }
}

// Extractions on several threads at once that read different sections of the volume's store
// (mode none its core alone, simplify every section): each gets its mesh, whichever converts the
// volume first, and whether the other waits for that store or for the one made again after it.
TEST_F(SourceOfAFile, ExtractionsThatReadDifferentSectionsAtOnceEachGetTheirMesh) {
  const std::string raw = copy_of("neghip_66x66x66_uint8.raw");
  const Source kept_store = converted(raw);
  const ExtractOptions none = coarse_in(TopologyMode::none, 128.5f, 4),
                       simplify = coarse_in(TopologyMode::simplify, 128.5f, 4, 10);
  const Mesh none_mesh = kept_store.extract(none), simplify_mesh = kept_store.extract(simplify);
  for (int round = 0; round < 3; ++round) {
    const Source source = open_volume(spec_of(raw));
    EXPECT_EQ(right_at_once(source, none, none_mesh, simplify, simplify_mesh, round % 2 == 1), 4) << "round " << round;
    EXPECT_GT(source.info().store_bytes, 0u) << "round " << round;
    EXPECT_LE(source.info().store_bytes, kept_store.info().store_bytes) << "round " << round;
  }
}

// A value that is not finite is refused by the extraction that reads it, in the words and at the
// coordinates the whole read gives.
TEST_F(SourceOfAFile, AValueThatIsNotFiniteIsRefusedWhereItIs) {
  std::vector<float> values(9 * 8 * 7, 1.0f);
  for (size_t i = 0; i < values.size(); i += 3) values[i] = -1.0f;
  values[(5 * 8 + 4) * 9 + 3] = std::numeric_limits<float>::quiet_NaN();  // (3, 4, 5)
  const std::string raw = path("nan_9x8x7_float32.raw");
  std::ofstream(raw, std::ios::binary)
      .write(reinterpret_cast<const char*>(values.data()), static_cast<std::streamsize>(values.size() * 4));
  const std::string whole = testing::io_error_of([&] { read_volume(spec_of(raw)); });
  EXPECT_CONTAINS(whole, "(3,4,5)");
  const Source source = open_volume(spec_of(raw));
  for (double eps : {0.0, 1.0}) {
    ExtractOptions o;
    o.eps = eps;
    const std::string streamed = testing::io_error_of([&] { source.extract(o); });
    EXPECT_CONTAINS(streamed, raw);
    EXPECT_CONTAINS(streamed, "(x,y,z) = (3,4,5)");
    EXPECT_CONTAINS(streamed, "not finite");
  }
}

// The check of an array's values finds the first value that is not finite in any block of its
// parallel scan (at a block's first and last value too), whatever comes after it, on any number of
// threads, of either sign and any mantissa; the largest finite floats, -0 and denormals pass.
TEST(FiniteValues, TheFirstValueThatIsNotFiniteIsFoundInAnyBlock) {
  constexpr size_t kBlock = size_t{1} << 16, kCount = 5 * kBlock + 123;
  std::vector<float> values(kCount);
  for (size_t i = 0; i < kCount; ++i)
    values[i] = std::array<float, 4>{std::numeric_limits<float>::max(), -std::numeric_limits<float>::max(), -0.0f,
                                     std::numeric_limits<float>::denorm_min()}[i % 4];
  for (size_t threads : {1, 2, 8}) {
    const tbb::global_control limit(tbb::global_control::max_allowed_parallelism, threads);
    EXPECT_EQ(first_non_finite(values.data(), kCount), kCount);
    EXPECT_EQ(first_non_finite(values.data(), 0), 0u);
    for (const size_t at : {size_t{0}, kBlock - 1, kBlock, 3 * kBlock + 7, kCount - 1}) {
      std::vector<float> bad = values;
      bad[at] = std::numeric_limits<float>::quiet_NaN();
      for (const size_t later : {at + 1, at + kBlock, kCount - 1})
        if (later < kCount && later > at) bad[later] = -std::numeric_limits<float>::infinity();
      EXPECT_EQ(first_non_finite(bad.data(), kCount), at) << threads << " threads";
      // Every value whose exponent bits are all set, whatever its sign and mantissa.
      for (const uint32_t bits : {0x7f800000u, 0xff800000u, 0xffc00000u, 0x7f800001u, 0xffffffffu}) {
        bad[at] = std::bit_cast<float>(bits);
        EXPECT_EQ(first_non_finite(bad.data(), kCount), at) << threads << " threads, bits " << bits;
      }
    }
  }
}

// An array handed over is checked when opened; a borrowed one, which its owner may change between
// extractions, again at each eps-0 extraction.
TEST(FiniteValues, ABorrowedArrayIsCheckedAgainAtEachExtraction) {
  std::vector<float> values = generate_sphere(33).values;
  Volume borrowed;
  borrowed.dims = {33, 33, 33};
  borrowed.borrowed = std::span<const float>(values);
  const Source source = open_volume(std::move(borrowed));
  ExtractOptions o;
  EXPECT_GT(source.extract(o).triangles.size(), 0u);
  values[(7 * 33 + 5) * 33 + 3] = std::numeric_limits<float>::quiet_NaN();
  std::string error;
  try {
    source.extract(o);
  } catch (const std::exception& e) {
    error = e.what();
  }
  EXPECT_CONTAINS(error, "(x,y,z) = (3,5,7) is not finite");
}

// A slab that throws stops the slabs after it from starting, and the failure hook runs (a march
// whose slabs wait on one another, as a streamed one's, needs it to release the others).
TEST(FullResolutionSlabs, AFailedSlabStopsTheRestAndCallsTheFailureHook) {
  SlabPlan plan;
  plan.cell_layers = 1000;
  plan.side = 1001;
  for (int threads : {1, 2}) {
    const tbb::global_control limit(tbb::global_control::max_allowed_parallelism, static_cast<size_t>(threads));
    std::atomic<int> marched{0}, hooked{0};
    try {
      march_in_slabs(
          plan,
          [&](int64_t z0, int64_t, MeshBuilder&) {
            if (z0 == 0) {  // once the other threads are well into their slabs
              std::this_thread::sleep_for(std::chrono::milliseconds(50));
              throw std::runtime_error("slab 0 failed");
            }
            ++marched;
            std::this_thread::sleep_for(std::chrono::milliseconds(2));
          },
          [&] {
            ++hooked;
            EXPECT_TRUE(std::current_exception() != nullptr);
          });
      ADD_FAILURE() << "the failure went unnoticed";
    } catch (const std::runtime_error& e) {
      EXPECT_EQ(std::string(e.what()), "slab 0 failed");
    }
    EXPECT_EQ(hooked, 1) << threads << " threads";
    EXPECT_LT(marched, 200) << threads << " threads: slabs went on after the failure";
  }
}

}  // namespace
}  // namespace isotope
