// The banded build (BandTile) against MultiresVolume::build: every record bit for bit,
// with the bands chained through nothing but each tile's next-band output, as the store writer
// chains them through its scratch files.
#include <gtest/gtest.h>
#include <sys/resource.h>
#include <tbb/global_control.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstring>
#include <map>
#include <mutex>

#include "engine/hierarchy/band_tile.h"
#include "engine/hierarchy/banded_build.h"
#include "engine/hierarchy/hierarchy.h"
#include "engine/hierarchy/multires_volume.h"
#include "engine/hierarchy/record_builder.h"
#include "engine/synthetic/fields.h"
#include "isotope/distribution.h"
#include "tests/support/test_support.h"

namespace isotope {
namespace {

// Band 0's input read from a volume in memory, as a ReadBox.
ReadBox read_from(const Volume& v) {
  return [&v](const Box3& lo, const Box3& size, float* out) {
    for (int64_t z = 0; z < size[2]; ++z)
      for (int64_t y = 0; y < size[1]; ++y)
        for (int64_t x = 0; x < size[0]; ++x) *out++ = v.at(lo[0] + x, lo[1] + y, lo[2] + z);
  };
}

struct NextBand {
  Box3 nodes{};
  std::vector<float> values;
  std::vector<Record> children;
  size_t at(const Box3& g) const { return static_cast<size_t>((g[2] * nodes[1] + g[1]) * nodes[0] + g[0]); }
};

bool same_bits(const Record& a, const Record& b) { return std::memcmp(&a, &b, sizeof(Record)) == 0; }

// Runs every band tile by tile (tiles of one brick, in any order) and checks each core record.
int64_t check_banded(const Volume& volume, int brick_bits) {
  const MultiresVolume mv = MultiresVolume::build(volume);
  const StoreLayout layout(volume.dims, brick_bits);
  const int64_t t = layout.brick_width();
  NextBand in;
  int64_t checked = 0;
  for (const Band& band : layout.bands()) {
    const int j = band.scale;
    NextBand out;
    if (j < layout.lattice().k) {
      out.nodes = layout.band(j + 1).nodes;
      out.values.assign(static_cast<size_t>(out.nodes[0] * out.nodes[1] * out.nodes[2]), NAN);
      out.children.resize(out.values.size());
    }
    for (int64_t bz = 0; bz < band.bricks[2]; ++bz)
      for (int64_t by = 0; by < band.bricks[1]; ++by)
        for (int64_t bx = 0; bx < band.bricks[0]; ++bx) {
          const Box3 lo{bx * t, by * t, bz * t};
          const Box3 hi{std::min(lo[0] + t, band.nodes[0]), std::min(lo[1] + t, band.nodes[1]),
                        std::min(lo[2] + t, band.nodes[2])};
          BandTile tile(layout, j, lo, hi);
          const Box3 s = tile.window_size();
          for (int64_t z = 0; z < s[2]; ++z)
            for (int64_t y = 0; y < s[1]; ++y)
              for (int64_t x = 0; x < s[0]; ++x) {
                const Box3 g{tile.window_lo()[0] + x, tile.window_lo()[1] + y, tile.window_lo()[2] + z};
                float v;
                if (j == 0) {
                  v = volume.at(std::min(g[0], volume.dims[0] - 1), std::min(g[1], volume.dims[1] - 1),
                                std::min(g[2], volume.dims[2] - 1));
                } else {
                  v = in.values[in.at({std::min(g[0], in.nodes[0] - 1), std::min(g[1], in.nodes[1] - 1),
                                       std::min(g[2], in.nodes[2] - 1)})];
                }
                tile.values()[static_cast<size_t>((z * s[1] + y) * s[0] + x)] = v;
                if (j > 0 && x + 1 < s[0] && y + 1 < s[1] && z + 1 < s[2] && g[0] < in.nodes[0] && g[1] < in.nodes[1] &&
                    g[2] < in.nodes[2])
                  tile.children()[static_cast<size_t>((z * (s[1] - 1) + y) * (s[0] - 1) + x)] = in.children[in.at(g)];
              }
          CriticalCounts counts = {{0, 0, 0}, {0, 0, 0}};
          tile.build(counts);
          for (int64_t z = lo[2]; z < hi[2]; ++z)
            for (int64_t y = lo[1]; y < hi[1]; ++y)
              for (int64_t x = lo[0]; x < hi[0]; ++x) {
                if (!((x | y | z) & 1) || j == layout.lattice().k) continue;
                const Coord v{x << j, y << j, z << j};
                EXPECT_TRUE(mv.has_record(v));
                const int64_t slot = mv.record_slot(v);
                const Record expected{mv.bounds(slot), mv.topology(slot)};
                EXPECT_TRUE(same_bits(tile.node_record({x, y, z}), expected))
                    << "band " << j << " node " << x << " " << y << " " << z;
                ++checked;
              }
          for (int64_t z = tile.next_lo()[2]; z < tile.next_hi()[2]; ++z)
            for (int64_t y = tile.next_lo()[1]; y < tile.next_hi()[1]; ++y)
              for (int64_t x = tile.next_lo()[0]; x < tile.next_hi()[0]; ++x) {
                out.values[out.at({x, y, z})] = tile.next_value({x, y, z});
                out.children[out.at({x, y, z})] = tile.next_child({x, y, z});
              }
        }
    for (float v : out.values) EXPECT_FALSE(std::isnan(v)) << "band " << j + 1 << " input not covered";
    in = std::move(out);
  }
  // Every record of the in-memory build was among them.
  int64_t records = 0;
  const Lattice& l = mv.lattice();
  for (int64_t z = 0; z <= l.n; ++z)
    for (int64_t y = 0; y <= l.n; ++y)
      for (int64_t x = 0; x <= l.n; ++x) records += scale_of({x, y, z}, l) < l.k && mv.has_record({x, y, z});
  EXPECT_EQ(checked, records);
  return checked;
}

// The builds fold children four fields at a time (ChildFold); Saturation::add is the fold one
// field at a time. Records of a few values, signed zeros and infinities among them, so that
// most folds meet ties, and intervals empty in several ways: every record the same bits.
TEST(BandBuild, TheVectorFoldOfChildrenIsTheScalarOne) {
  const float pool[] = {0.0f, -0.0f, 1.0f, -1.0f, 2.5f, INFINITY, -INFINITY, 1e-3f};
  uint64_t state = 12345;
  auto pick = [&] {
    state = state * 6364136223846793005ull + 1442695040888963407ull;
    return pool[(state >> 33) % std::size(pool)];
  };
  // An interval, or none as every record a build writes holds it (DiamondTopology).
  auto interval = [&](float& lo, float& hi) {
    lo = pick(), hi = pick();
    if (!(lo < hi) || (state >> 40) % 4 == 0) lo = DiamondTopology::kNone, hi = -DiamondTopology::kNone;
  };
  int64_t differing = 0, nonempty = 0;
  for (int trial = 0; trial < 20000; ++trial) {
    DiamondBounds range{pick(), pick(), 0, 0};
    if (range.hi < range.lo) std::swap(range.lo, range.hi);
    const int children = static_cast<int>(trial % 9);
    std::vector<Record> c(static_cast<size_t>(children));
    for (Record& r : c) {
      r.bounds = {pick(), pick(), std::fabs(pick()), std::fabs(pick())};
      interval(r.topology.exact_lo, r.topology.exact_hi);
      interval(r.topology.paper_lo, r.topology.paper_hi);
      r.topology.weight = {std::fabs(pick()), std::fabs(pick()), std::fabs(pick())};
    }
    for (bool topology : {true, false}) {
      Saturation scalar;
      DiamondBounds scalar_range = range;
      ChildFold fold(range);
      for (const Record& r : c) {
        scalar.add(r, scalar_range, topology);
        fold.add(r, topology);
      }
      DiamondBounds fold_range = range;
      const Saturation folded = fold.finish(fold_range);
      // v between a and b: the record's intervals and weights are its children's alone.
      DiamondValues dv;
      dv.fa = 0, dv.fb = 2, dv.fv = 1;
      const DiamondShape shape;
      CriticalCounts counts = {{0, 0, 0}, {0, 0, 0}};
      const Record a = finish_record(dv, shape, true, scalar_range, scalar, counts, topology);
      const Record b = finish_record(dv, shape, true, fold_range, folded, counts, topology);
      differing += !same_bits(a, b);
      nonempty += !scalar.exact.empty();
    }
  }
  EXPECT_EQ(differing, 0);
  EXPECT_GT(nonempty, 5000);  // the hulls were exercised
}

// The band tile takes a vertex's range four values at a time where no value of its window is -0,
// in the order of read_polyhedron where one is: between -0 and 0, the first met. Values of -0, 0
// and 1 in one corner of the volume and 0 and 1 elsewhere: tiles of either kind, and ties
// between -0 and 0 wherever the corner reaches.
TEST(BandBuild, EqualsInMemoryBuildWithSignedZeros) {
  Volume v;
  v.dims = {37, 29, 33};
  v.values.resize(static_cast<size_t>(v.node_count()));
  uint64_t state = 99;
  for (int64_t z = 0; z < v.dims[2]; ++z)
    for (int64_t y = 0; y < v.dims[1]; ++y)
      for (int64_t x = 0; x < v.dims[0]; ++x) {
        state = state * 6364136223846793005ull + 1442695040888963407ull;
        const uint64_t r = (state >> 33) % 3;
        const bool corner = x < 12 && y < 12 && z < 12;
        v.values[v.index(x, y, z)] = r == 2 ? 1.0f : (r == 1 && corner ? -0.0f : 0.0f);
      }
  for (int bits : {2, 3}) EXPECT_GT(check_banded(v, bits), v.node_count() / 2);
}

TEST(BandBuild, EqualsInMemoryBuildOnOddDimensions) {
  for (const auto& dims : std::vector<Box3>{{2, 2, 2}, {3, 5, 2}, {17, 17, 17}, {30, 19, 23}, {41, 9, 70}}) {
    const Volume v = testing::crop(generate_noise(70, 7), dims);
    for (int bits : {1, 2, 3}) {
      const int64_t checked = check_banded(v, bits);
      if (dims[0] > 2) {
        EXPECT_GT(checked, v.node_count() / 2);
      }
    }
  }
}

TEST(BandBuild, EqualsInMemoryBuildOnRealVolume) {
  for (const auto& shared : testing::shared_volumes()) {
    const Volume v = testing::load_shared(shared);
    EXPECT_GT(check_banded(v, 4), v.node_count() / 2) << shared.name;
  }
}

// ---- The stage: a group of tiles reads its input and hand-over at once, and writes what it
// hands the next band a row at a time; the output does not change.

// Every brick's values and records, as the sink saw them, and the order of the commits.
struct RecordingSink {
  explicit RecordingSink(const StoreLayout* l) : layout(l) {}
  const StoreLayout* layout;
  std::map<int64_t, std::vector<uint8_t>> bricks;
  std::vector<int64_t> order;
  std::vector<uint8_t> process(int band, const Box3& b, const BandTile& tile) const {
    std::vector<uint8_t> bytes;
    const int64_t t = layout->brick_width();
    const Band& bd = layout->band(band);
    for (int64_t z = b[2] * t; z < std::min((b[2] + 1) * t, bd.nodes[2]); ++z)
      for (int64_t y = b[1] * t; y < std::min((b[1] + 1) * t, bd.nodes[1]); ++y)
        for (int64_t x = b[0] * t; x < std::min((b[0] + 1) * t, bd.nodes[0]); ++x) {
          const float v = tile.node_value({x, y, z});
          const auto* p = reinterpret_cast<const uint8_t*>(&v);
          bytes.insert(bytes.end(), p, p + sizeof v);
          if (((x | y | z) & 1) && band < layout->lattice().k) {
            const auto* r = reinterpret_cast<const uint8_t*>(&tile.node_record({x, y, z}));
            bytes.insert(bytes.end(), r, r + sizeof(Record));
          }
        }
    return bytes;
  }
  void commit(int band, const Box3& b, std::vector<uint8_t>&& bytes) {
    const int64_t i = layout->brick_index(band, b);
    order.push_back(i);
    bricks[i] = std::move(bytes);
  }
  // Held in a map by Morton code: released in Morton order.
  std::map<uint64_t, std::pair<int, Box3>> held;
  void hold(int band, const Box3& b, std::vector<uint8_t>&& bytes) {
    const int64_t i = layout->brick_index(band, b);
    held[morton_encode(static_cast<uint64_t>(b[0]), static_cast<uint64_t>(b[1]), static_cast<uint64_t>(b[2]))] = {band,
                                                                                                                  b};
    bricks[i] = std::move(bytes);
  }
  void release() {
    for (const auto& [code, at] : held) order.push_back(layout->brick_index(at.first, at.second));
    held.clear();
  }
};

// A hand-over in memory that counts the calls made to it: a scratch file's cost.
class CountingHandover : public MemoryHandover {
 public:
  using MemoryHandover::MemoryHandover;
  bool in_memory() const override { return false; }
  void write_box(const Box3& lo, const Box3& hi, const float* v, const Record* r, int64_t row, int64_t plane) override {
    ++calls;
    MemoryHandover::write_box(lo, hi, v, r, row, plane);
  }
  void read_values(const Box3& lo, const Box3& hi, float* out, int64_t row, int64_t plane) const override {
    ++calls;
    MemoryHandover::read_values(lo, hi, out, row, plane);
  }
  void read_children(const Box3& lo, const Box3& hi, Record* out, int64_t row, int64_t plane) const override {
    ++calls;
    MemoryHandover::read_children(lo, hi, out, row, plane);
  }
  mutable std::atomic<int64_t> calls{0};
};

struct StagedRun {
  RecordingSink sink;
  int64_t handover_calls = 0;
};

// The whole build, band by band, each band's tiles cut into RANKS runs of its Morton order built
// one after the other from the last to the first (as the ranks of a distributed convert, which
// share one hand-over file: a run that wrote rows beyond its own tiles would overwrite the rows of
// a run built before it).
StagedRun build_staged(const Volume& v, const StoreLayout& layout, bool staged, int64_t stage_tiles, int ranks) {
  const ReadBox read = read_from(v);
  StagedRun run{RecordingSink(&layout), 0};
  std::unique_ptr<CountingHandover> in;
  for (const Band& band : layout.bands()) {
    const int j = band.scale;
    std::unique_ptr<CountingHandover> next;
    if (j < layout.lattice().k) next = std::make_unique<CountingHandover>(layout.band(j + 1).nodes);
    const size_t tiles = tile_count(band, 1);
    std::vector<RecordingSink> parts;
    for (int r = ranks - 1; r >= 0; --r) {
      BandedBuildOptions o;
      o.first_band = o.last_band = j;
      o.tile_bricks = 1;
      o.first_tile = tiles * static_cast<size_t>(r) / static_cast<size_t>(ranks);
      o.last_tile = tiles * static_cast<size_t>(r + 1) / static_cast<size_t>(ranks);
      o.handover_in = in.get();
      o.handover_out = next.get();
      o.staged = staged;
      o.stage_tiles = stage_tiles;
      RecordingSink part(&layout);
      build_bands(layout, read, part, 0, o);
      parts.insert(parts.begin(), std::move(part));
    }
    for (RecordingSink& part : parts) {  // in rank order, as the store places the runs
      run.sink.order.insert(run.sink.order.end(), part.order.begin(), part.order.end());
      run.sink.bricks.merge(part.bricks);
    }
    if (in) run.handover_calls += in->calls;
    in = std::move(next);
  }
  return run;
}

// Odd sizes: groups cut by the volume's far faces, bands of a few tiles, the corners.
void expect_staged_groups_build_what_their_tiles_build_alone(const Box3& dims) {
  const Volume v = testing::crop(generate_noise(70, 11), dims);
  const StoreLayout layout(v.dims, 2);  // bricks and tiles of 4^3 nodes: 70x53x61 has 18 x 14 x 16 in band 0
  for (int ranks : {1, 3}) {
    SCOPED_TRACE(::testing::Message() << dims[0] << "x" << dims[1] << "x" << dims[2] << ", " << ranks << " ranks");
    const StagedRun alone = build_staged(v, layout, false, 0, ranks);
    EXPECT_EQ(alone.sink.bricks.size(), static_cast<size_t>(layout.brick_count()));
    for (int64_t s : {2, 4, 32}) {
      SCOPED_TRACE(::testing::Message() << "groups of " << s << "^3 tiles");
      const StagedRun staged = build_staged(v, layout, true, s, ranks);
      EXPECT_TRUE(staged.sink.bricks == alone.sink.bricks);
      EXPECT_EQ(staged.sink.order, alone.sink.order);  // file order
      // A row of a group's box instead of a row of each tile's: s times fewer, less the halo,
      // while the groups are smaller than the bands (the grid of band 1 is at most 9 tiles across).
      EXPECT_LT(staged.handover_calls * std::min<int64_t>(s, 8), alone.handover_calls * 2)
          << staged.handover_calls << " calls staged, " << alone.handover_calls << " alone";
    }
  }
}

TEST(BandBuild, AStagedGroupOfTilesBuildsWhatItsTilesBuildAloneInFewerCalls) {
  expect_staged_groups_build_what_their_tiles_build_alone({33, 70, 9});
  const Volume v = testing::crop(generate_noise(70, 11), {70, 53, 61});
  const StoreLayout layout(v.dims, 2);
  BandedBuildOptions o;
  o.staged = true;  // hand-overs in memory: no stage (one more copy for nothing), the same bricks
  RecordingSink budgeted(&layout);
  build_bands(layout, read_from(v), budgeted, 0, o);
  EXPECT_TRUE(budgeted.bricks == build_staged(v, layout, false, 0, 1).sink.bricks);
  EXPECT_GE(stage_tiles_for(layout, 0, 1, o.memory_bytes), 16);
  EXPECT_EQ(stage_tiles_for(layout, 0, 1, 1 << 10), 0);  // not even 2^3 tiles fit: no stage
}

// The same over a larger volume, in its own test so that the race-checking build, which runs the
// smaller one above, can leave it out.
TEST(BandBuild, StagedGroupsOfALargerVolumeBuildWhatTheirTilesBuildAlone) {
  expect_staged_groups_build_what_their_tiles_build_alone({70, 53, 61});
}

// Fused tiles of 128^3 nodes where band 0 has at least 64 of them a thread (fewer halo records
// computed twice), of 64^3 otherwise (the last tiles would leave threads idle), smaller still where
// the budget asks it; fused, an even number of bricks of at least 64 nodes. Tiles that are not
// fused: 32^3 nodes, whose records stay in cache.
TEST(BandBuild, LargeVolumesTakeLargerFusedTilesWhereEveryThreadHasManyOfThem) {
  const uint64_t gib = uint64_t{1} << 30;
  const StoreLayout large({1025, 1025, 1025}, 4), small({513, 513, 513}, 4), coarse({1025, 1025, 1025}, 6);
  {
    const tbb::global_control two(tbb::global_control::max_allowed_parallelism, 2);
    EXPECT_EQ(tile_bricks_for(large, 4096, gib, true), 8);  // 9^3 tiles of 128^3 nodes: 364 a thread
    EXPECT_EQ(fused_tile_bricks_for(large, 4096, gib), 8);
    EXPECT_EQ(tile_bricks_for(small, 4096, gib, true), 4);  // 5^3 tiles of 128^3: 62 a thread
    EXPECT_EQ(fused_tile_bricks_for(small, 4096, gib), 4);
    EXPECT_LT(tile_bricks_for(large, 4096, 256 << 20, true), 8);  // a 128^3 tile's window would not fit
    EXPECT_EQ(tile_bricks_for(large, 4096, gib), 2);
    EXPECT_EQ(tile_bricks_for(small, 4096, gib), 2);
    EXPECT_EQ(tile_bricks_for(coarse, 4096, gib), 1);  // a brick of 64^3 nodes: no smaller tile
  }
  {
    // (global_control keeps the least of the values set: one at a time.)
    const tbb::global_control many(tbb::global_control::max_allowed_parallelism, 16);
    EXPECT_EQ(fused_tile_bricks_for(large, 4096, 16 * gib), 4);  // 45 a thread
  }
}

// A band too small for sixteen full tiles a thread takes smaller tiles, so that the coarse bands, or
// band 0 of a small volume, are not one thread's work and fault in less memory; on one thread, the
// tiles chosen.
TEST(BandBuild, SmallBandsTakeSmallerTilesOnSeveralThreads) {
  const StoreLayout embryo({256, 256, 256}, 4), neghip({66, 66, 66}, 4), hundred({100, 100, 100}, 4),
      mid({128, 128, 128}, 4);
  {
    const tbb::global_control two(tbb::global_control::max_allowed_parallelism, 2);
    EXPECT_EQ(band_tile_bricks(embryo, embryo.band(0), 2), 2);    // 257^3 nodes: 259 tiles of 32^3 a thread
    EXPECT_EQ(band_tile_bricks(mid, mid.band(0), 2), 2);          // 129^3: 33 a thread
    EXPECT_EQ(band_tile_bricks(embryo, embryo.band(2), 2), 1);    // 65^3: 4.2 a thread: tiles of 16^3
    EXPECT_EQ(band_tile_bricks(embryo, embryo.band(3), 2), 1);    // 33^3: tiles of 16^3
    EXPECT_EQ(band_tile_bricks(embryo, embryo.band(5), 2), 1);    // a brick: no smaller tile
    EXPECT_EQ(band_tile_bricks(neghip, neghip.band(0), 4), 1);    // 66^3: 4.4 tiles of 32^3 a thread
    EXPECT_EQ(band_tile_bricks(hundred, hundred.band(0), 4), 1);  // 101^3: 15.7 tiles of 32^3 a thread
  }
  {
    const tbb::global_control one(tbb::global_control::max_allowed_parallelism, 1);
    EXPECT_EQ(band_tile_bricks(embryo, embryo.band(3), 2), 2);
    EXPECT_EQ(band_tile_bricks(neghip, neghip.band(0), 4), 4);
  }
}

// ---- A fused pass: band j+1 built beside band j, each of its tiles from a widened tile of band j,
// where the hand-over between them would be a file; the output does not change.

// Odd sizes, and sides one short of a multiple of the tiles' (63 data nodes: band 0 has 64, its
// records reaching one node beyond the data, band 1 has 33: one node beyond band 0's last tile).
void expect_bands_built_beside_as_from_their_hand_over(const Box3& dims) {
  const Volume v = testing::crop(generate_noise(70, 13), dims);
  const StoreLayout layout(v.dims, 2);  // bricks of 4^3 nodes
  const StagedRun alone = build_staged(v, layout, false, 0, 1);
  const ReadBox read = read_from(v);
  for (int64_t c : {2, 4})
    for (bool staged : {false, true}) {
      SCOPED_TRACE(::testing::Message() << dims[0] << "x" << dims[1] << "x" << dims[2] << ", tiles of " << c
                                        << "^3 bricks" << (staged ? ", staged" : ""));
      std::map<int, int64_t> calls;  // per band, the calls made to the hand-over it reads
      struct Tallied : CountingHandover {
        Tallied(const Box3& nodes, int64_t& total) : CountingHandover(nodes), total_(total) {}
        ~Tallied() override { total_ += calls; }
        int64_t& total_;
      };
      BandedBuildOptions o;
      o.fuse = true;
      o.tile_bricks = c;
      o.staged = staged;
      o.make_handover = [&](const Box3& nodes, uint64_t) -> std::unique_ptr<BandHandover> {
        for (const Band& b : layout.bands())
          if (b.nodes == nodes) return std::make_unique<Tallied>(nodes, calls[b.scale]);
        ADD_FAILURE() << "a hand-over to no band";
        return nullptr;
      };
      RecordingSink fused(&layout);
      const BandedBuildStats stats = build_bands(layout, read, fused, 0, o);
      EXPECT_TRUE(fused.bricks == alone.sink.bricks);
      EXPECT_EQ(fused.order, alone.sink.order);  // file order
      // Bands 0 and 1 in one pass, 2 and 3 in the next, ...: the hand-overs into bands 1, 3, ...
      // are made (to learn they would be files) but never used.
      const int k = layout.lattice().k;
      EXPECT_EQ(stats.bands_built_beside, (k + 1) / 2);
      for (int j = 1; j <= k; ++j)
        if (j % 2)
          EXPECT_EQ(calls[j], 0) << "band " << j;
        else
          EXPECT_GT(calls[j], 0) << "band " << j;
    }
  // Tiles of one brick (band j+1's would be half a brick) and hand-overs in memory: no fused pass.
  for (int64_t c : {1, 2}) {
    BandedBuildOptions o;
    o.fuse = true;
    o.tile_bricks = c;
    if (c == 1) o.make_handover = [](const Box3& nodes, uint64_t) { return std::make_unique<CountingHandover>(nodes); };
    RecordingSink sink(&layout);
    EXPECT_EQ(build_bands(layout, read, sink, 0, o).bands_built_beside, 0);
    EXPECT_TRUE(sink.bricks == alone.sink.bricks);
  }
}

TEST(BandBuild, ABandBuiltBesideTheOneBeforeItIsTheBandBuiltFromItsHandOver) {
  for (const Box3& dims : std::vector<Box3>{{33, 70, 9}, {64, 40, 17}})
    expect_bands_built_beside_as_from_their_hand_over(dims);
}

// The same over larger volumes, in their own test so that the race-checking build, which runs the
// smaller ones above, can leave them out.
TEST(BandBuild, BandsOfLargerVolumesBuiltBesideAreBuiltFromTheirHandOver) {
  for (const Box3& dims : std::vector<Box3>{{70, 53, 61}, {63, 47, 31}})
    expect_bands_built_beside_as_from_their_hand_over(dims);
}

// A hierarchy held in memory keeps the store's 16^3 bricks for every volume of usual shape, and
// takes smaller ones where those would be mostly padding (StoreLayout::memory_brick_bits): a
// 500000x2x2 volume in 16^3 bricks held 28 slots a node and took 4.0 GB for 2 MB of data. The mesh
// does not depend on the bricks.
// A slow tile holds up only the commits after it: the tiles after it go on being built, up to the
// tiles in flight, where runs of that many tiles, each waited for before the next began, left a
// thread idle at each run's end. Here tile 1 finishes only once tile W (the first beyond a run of
// W, the tiles in flight) has begun: it would wait for ever in runs, and a timeout fails it.
// A hand-over in memory has its pages in memory before the tiles write it, a few rows at a time:
// writing it whole takes (almost) no page fault on the writing thread.
TEST(BandBuild, AHandoverInMemoryIsFaultedInBeforeTheTilesWriteIt) {
#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
  GTEST_SKIP() << "a sanitizer's writes fault in its own shadow memory";
#else
  const Box3 n{129, 129, 129};  // 8.6 MB of values and more of records
  MemoryHandover h(n);
  const int64_t row = n[0], plane = n[0] * n[1];
  std::vector<float> values(static_cast<size_t>(plane * kHandoverBlock), 1.5f);
  std::vector<Record> records(values.size());
  rusage before{}, after{};
  getrusage(RUSAGE_THREAD, &before);
  for (int64_t z = 0; z < n[2]; z += kHandoverBlock)
    h.write_box({0, 0, z}, {n[0], n[1], std::min(n[2], z + kHandoverBlock)}, values.data(), records.data(), row, plane);
  getrusage(RUSAGE_THREAD, &after);
  const auto pages = static_cast<long>(BandHandover::bytes(n) / 4096);
  EXPECT_LT(after.ru_minflt - before.ru_minflt, pages / 100) << "of " << pages << " pages";
  float v = 0;
  h.read_values({5, 6, 128}, {6, 7, 129}, &v, 1, 1);
  EXPECT_EQ(v, 1.5f);
#endif
}

// So do a hierarchy's arrays before its build writes them, a brick at a time: every field of
// every brick written on this thread takes (almost) no page fault.
TEST(BandBuild, AHierarchysArraysAreFaultedInBeforeItsBuildWritesThem) {
#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
  GTEST_SKIP() << "a sanitizer's writes fault in its own shadow memory";
#else
  const RecordFields all{true, true, true, true};
  Hierarchy h = Hierarchy::allocate({129, 129, 129}, 4, all);  // 84 MB
  const int64_t nodes = h.layout().brick_nodes();
  rusage before{}, after{};
  getrusage(RUSAGE_THREAD, &before);
  for (int64_t index = 0; index < h.layout().brick_count(); ++index) {
    const BrickView b = h.brick(index);
    std::fill_n(h.values(index), nodes, 1.5f);
    std::fill_n(b.bounds, nodes, uint64_t{7});
    std::fill_n(b.surplus, nodes, uint16_t{7});
    std::fill_n(b.exact, nodes, 7u);
    std::fill_n(b.paper, nodes, 7u);
    std::fill_n(b.weights, nodes, uint64_t{7});
  }
  getrusage(RUSAGE_THREAD, &after);
  const auto pages = static_cast<long>(h.memory_bytes() / 4096);
  EXPECT_LT(after.ru_minflt - before.ru_minflt, pages / 100) << "of " << pages << " pages";
  EXPECT_EQ(h.values_data()[h.layout().brick_count() * nodes - 1], 1.5f);
#endif
}

// What a hierarchy in memory will take is known before it is built (Hierarchy::memory_bytes of the
// dimensions and fields), for a cube and for thin volumes, whose bricks build() takes smaller
// (memory_brick_bits), with every field, none, or some.
TEST(BandBuild, AHierarchysMemoryIsKnownBeforeItIsBuilt) {
  const std::array<std::array<int64_t, 3>, 3> shapes = {{{33, 30, 35}, {300, 2, 3}, {60, 50, 2}}};
  const RecordFields some{/*exact=*/true, /*paper=*/false, /*weights=*/false, /*surplus=*/true};
  const RecordFields none{false, false, false, false};
  for (const auto& dims : shapes)
    for (const RecordFields& fields : {RecordFields{}, some, none}) {
      Volume v;
      v.dims = dims;
      v.values.resize(static_cast<size_t>(v.node_count()));
      for (size_t i = 0; i < v.values.size(); ++i) v.values[i] = static_cast<float>(i % 7);
      const Hierarchy h = Hierarchy::build(v, fields);
      EXPECT_EQ(Hierarchy::memory_bytes(dims, fields), h.memory_bytes())
          << dims[0] << "x" << dims[1] << "x" << dims[2] << ", " << fields.exact << fields.paper << fields.weights
          << fields.surplus;
      EXPECT_GT(h.memory_bytes(), 0);
    }
}

TEST(BandBuild, ASlowTileHoldsUpOnlyTheCommitsAfterIt) {
  const tbb::global_control two(tbb::global_control::max_allowed_parallelism, 2);
  if (thread_count() < 2) GTEST_FAIL() << "needs two threads";
  const Volume v = generate_noise(33, 5);
  const StoreLayout layout(v.dims, 2);  // band 0: 9^3 bricks, tiles of one brick
  const std::vector<Box3> order = in_morton_order(layout.band(0).bricks);
  struct WaitingSink : RecordingSink {
    using RecordingSink::RecordingSink;
    std::vector<Box3> order;
    int64_t window = -1;  // -1: no tile waits
    std::mutex mutex;
    std::condition_variable begun;
    bool last_begun = false, timed_out = false;
    std::vector<uint8_t> process(int band, const Box3& b, const BandTile& tile) {
      if (window < 0) return RecordingSink::process(band, b, tile);
      if (band == 0 && b == order[static_cast<size_t>(window)]) {
        const std::lock_guard<std::mutex> lock(mutex);
        last_begun = true;
        begun.notify_all();
      }
      if (band == 0 && b == order[1]) {
        std::unique_lock<std::mutex> lock(mutex);
        if (!begun.wait_for(lock, std::chrono::seconds(20), [&] { return last_begun; })) timed_out = true;
      }
      return RecordingSink::process(band, b, tile);
    }
  };
  BandedBuildOptions o;
  o.tile_bricks = 1;
  // The tiles in flight, as build_bands counts them (a build reports it): four on two threads.
  WaitingSink probe(&layout);
  probe.order = order;
  const int64_t window = build_bands(layout, read_from(v), probe, 0, o).tiles_in_flight;
  ASSERT_GE(window, 3);
  ASSERT_LT(window, static_cast<int64_t>(order.size()));
  WaitingSink sink(&layout);
  sink.order = order;
  sink.window = window;
  build_bands(layout, read_from(v), sink, 0, o);
  EXPECT_FALSE(sink.timed_out) << "tile " << window << " did not begin while tile 1 was being built";
  EXPECT_TRUE(sink.bricks == probe.bricks);
  EXPECT_EQ(sink.order, probe.order);
}

TEST(BandBuild, AHierarchyInMemoryPadsLittleWhateverTheVolumesShape) {
  auto slots_per_node = [](const Box3& dims, int bits) {
    const StoreLayout layout(dims, bits);
    int64_t nodes = 0;
    for (const Band& b : layout.bands()) nodes += b.nodes[0] * b.nodes[1] * b.nodes[2];
    return static_cast<double>(layout.brick_count() << (3 * bits)) / static_cast<double>(nodes);
  };
  std::vector<Box3> usual = {{33, 33, 33},    {129, 129, 129},    {65, 65, 65},    {257, 257, 257},
                             {513, 513, 513}, {2049, 2049, 2049}, {512, 512, 300}, {301, 324, 56}};
  for (const auto& shared : testing::shared_volumes()) usual.push_back(testing::load_shared(shared).dims);
  for (const Box3& dims : usual) EXPECT_EQ(StoreLayout::memory_brick_bits(dims), 4) << dims[0] << "x" << dims[1];
  for (const Box3& dims : std::vector<Box3>{{500000, 2, 2}, {2000, 2000, 2}, {1000, 3, 3}, {4096, 4096, 3}}) {
    EXPECT_GT(slots_per_node(dims, 4), 4.0) << dims[0] << "x" << dims[1] << "x" << dims[2];
    EXPECT_LE(slots_per_node(dims, StoreLayout::memory_brick_bits(dims)), 3.0) << dims[0] << "x" << dims[1];
  }
  const Volume thin = testing::crop(generate_noise(70, 7), {70, 3, 2});
  ASSERT_LT(StoreLayout::memory_brick_bits(thin.dims), 4);
  ExtractOptions o;
  o.iso = thin.values[thin.values.size() / 2];  // a surface through the middle
  o.eps = 0.05;
  const RecordFields all{true, true, true, true};
  const Mesh chosen = extract(Hierarchy::build(thin, all), o),
             store_bricks = extract(Hierarchy::build(thin, all, 4), o);
  EXPECT_GT(chosen.triangles.size(), 0u);
  EXPECT_TRUE(chosen.positions == store_bricks.positions && chosen.triangles == store_bricks.triangles);
}

// A distributed convert cuts each band's tiles, in Morton order, into one run per rank. Tiles at
// the grid's far faces are thin and come last, so runs of equal tile counts gave the last rank
// half the nodes of the first (513^3, tiles of 64 nodes: 8 full tiles and one of 1 node a side).
// Runs cut by tile_costs hold about equal numbers of nodes.
TEST(BandBuild, RanksGetRunsOfTilesOfAboutEqualNodes) {
  int checked = 0;
  for (const Box3& dims : std::vector<Box3>{{513, 513, 513}, {300, 200, 129}, {257, 257, 257}})
    for (const int64_t c : {2, 4}) {
      const StoreLayout layout(dims, 4);
      for (const Band& band : layout.bands()) {
        const std::vector<double> costs = tile_costs(layout, band, c);
        ASSERT_EQ(costs.size(), tile_count(band, c));
        // Each a tile's core, as build_bands cuts it; together every node of the band once.
        const int64_t side = c * layout.brick_width();
        const std::vector<Box3> tiles = in_morton_order(tile_grid(band, c));
        double total = 0;
        for (size_t i = 0; i < tiles.size(); ++i) {
          double nodes = 1;
          for (int a = 0; a < 3; ++a)
            nodes *= static_cast<double>(std::min((tiles[i][a] + 1) * side, band.nodes[a]) - tiles[i][a] * side);
          ASSERT_EQ(costs[i], nodes);
          total += nodes;
        }
        ASSERT_EQ(total, static_cast<double>(band.nodes[0] * band.nodes[1] * band.nodes[2]));
        if (tiles.size() < 64) continue;  // too few tiles to share evenly
        for (const int ranks : {2, 3}) {
          const std::vector<size_t> bounds = share_by_cost(costs, ranks);
          double most = 0, least = total;
          for (int r = 0; r < ranks; ++r) {
            double nodes = 0;
            for (size_t i = bounds[static_cast<size_t>(r)]; i < bounds[static_cast<size_t>(r) + 1]; ++i)
              nodes += costs[i];
            most = std::max(most, nodes);
            least = std::min(least, nodes);
          }
          EXPECT_LE(most, 1.1 * least) << dims[0] << "x" << dims[1] << "x" << dims[2] << " band " << band.scale
                                       << " tiles of " << c << " bricks, " << ranks << " ranks";
          ++checked;
        }
      }
    }
  EXPECT_GE(checked, 8);
}

}  // namespace
}  // namespace isotope
