// The store (docs/FORMAT.md): what a store holds, read back as an extraction reads it, is the
// in-memory hierarchy bit for bit (and that is the exact records conservatively rounded); the same
// meshes; the file does not depend on threads or the memory budget; every corruption is caught,
// named, and never crashes, by verify and by the reads an extraction makes.
#include <gtest/gtest.h>
#include <hdf5.h>
#include <sys/mman.h>
#include <zstd.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <mutex>
#include <random>

#include "engine/extract/extract_drivers.h"
#include "engine/extract/traversal.h"
#include "engine/hierarchy/banded_build.h"
#include "engine/hierarchy/compact_record.h"
#include "engine/hierarchy/hierarchy.h"
#include "engine/hierarchy/multires_volume.h"
#include "engine/synthetic/fields.h"
#include "io/store/brick_cache.h"
#include "io/store/brick_pool.h"
#include "io/store/handover_file.h"
#include "io/store/paged_volume.h"
#include "io/store/store_reader.h"
#include "io/store/store_writer.h"
#include "io/volume/box_reader.h"
#include "io/volume/held_box_reader.h"
#include "io/volume/volume_box_reader.h"
#include "isotope/convert.h"
#include "isotope/error.h"
#include "tbb/global_control.h"
#include "tests/support/byte_files.h"
#include "tests/support/io_error_of.h"
#include "tests/support/temp_dir_test.h"
#include "tests/support/test_support.h"

namespace isotope {

// A cache that keeps no brick but those its readers hold (BrickCache's friend): every miss evicts
// all the others, so a reader that reads a brick it does not hold reads it decoded again.
struct BrickCacheTesting {
  static void keep_only_what_readers_hold(BrickCache& cache) {
    const std::lock_guard<std::mutex> lock(cache.clock_mutex_);
    cache.working_ = 0;
    // Never a full window of misses, so never the whole budget (BrickCache::admit).
    cache.window_misses_ = std::numeric_limits<int64_t>::min() / 2;
  }
};

namespace {

using testing::io_error_of;
using testing::read_bytes;
using testing::TempDirTest;

// The IoError's message, or "" when f succeeds (anything else thrown fails the test).
std::string message_of(const std::function<void()>& f) {
  try {
    f();
  } catch (const IoError& e) {
    return e.what();
  }
  return "";
}

std::string dims_name(const Volume& v) {
  return std::to_string(v.dims[0]) + "x" + std::to_string(v.dims[1]) + "x" + std::to_string(v.dims[2]);
}

const RecordFields kAll{true, true, true, true};

// The store read whole, as an extraction reads it, with these fields.
Hierarchy load(const std::string& store, const RecordFields& fields = kAll) {
  const StoreReader reader(store);
  BrickCache cache(reader, uint64_t{1} << 34);
  const PagedVolume volume(cache);
  return load_hierarchy(volume, fields);
}

bool same_words(const Hierarchy& a, const Hierarchy& b, int64_t index, int64_t n) {
  const BrickView x = a.brick(index), y = b.brick(index);
  const auto bytes = static_cast<size_t>(n);
  // A field neither holds is the same; one only one holds is not.
  auto same = [&](const void* p, const void* q, size_t width) {
    return p == q || (p && q && std::memcmp(p, q, bytes * width) == 0);
  };
  return same(x.values, y.values, 4) && same(x.bounds, y.bounds, 8) && same(x.surplus, y.surplus, 2) &&
         same(x.exact, y.exact, 4) && same(x.paper, y.paper, 4) && same(x.weights, y.weights, 8);
}

class Store : public TempDirTest {
 protected:
  // Writes `v` as float32 raw and converts it; returns the store's path.
  std::string convert(const Volume& v, const std::string& name, const ConvertOptions& options = {},
                      const RunContext& run = {}) {
    return testing::write_store(v, dir_.string(), name, options, run);
  }

  // Every value and record of the store, read as an extraction reads it (band 0's records
  // computed from the values), equals the in-memory build's bit for bit, and each record is the
  // exact one (MultiresVolume) rounded to a compact record (docs/FORMAT.md, "Compact records").
  void expect_round_trip(const Volume& v, const std::string& store, int brick_bits = kDefaultBrickBits) {
    const Hierarchy loaded = load(store);
    const Hierarchy built = Hierarchy::build(v, kAll, brick_bits);
    ASSERT_EQ(loaded.layout().brick_count(), built.layout().brick_count());
    int64_t mismatches = 0;
    for (int64_t i = 0; i < built.layout().brick_count(); ++i)
      if (!same_words(loaded, built, i, built.layout().brick_nodes()) && ++mismatches < 5)
        ADD_FAILURE() << "brick " << i << " differs from the in-memory build";
    EXPECT_EQ(mismatches, 0);
    for (int t = 0; t < 3; ++t) {
      EXPECT_EQ(loaded.stats().critical_paper[t], built.stats().critical_paper[t]);
      EXPECT_EQ(loaded.stats().critical_exact[t], built.stats().critical_exact[t]);
    }
    // Against the exact records of the reference build, through the traversal's reader.
    const MultiresVolume exact = MultiresVolume::build(v);
    const Lattice& l = exact.lattice();
    Hierarchy::Reader reader = loaded.reader();
    int64_t records = 0;
    mismatches = 0;
    for (int64_t z = 0; z <= l.n; ++z)
      for (int64_t y = 0; y <= l.n; ++y)
        for (int64_t x = 0; x <= l.n; ++x) {
          const Coord c{x, y, z};
          if (x < v.dims[0] && y < v.dims[1] && z < v.dims[2]) {
            const float a = reader.value(c, 0), b = exact.value(c);
            mismatches += std::memcmp(&a, &b, sizeof a) != 0;
          }
          if (scale_of(c, l) == l.k || !exact.has_record(c)) continue;
          ++records;
          const int64_t slot = exact.record_slot(c);
          const Record expected = round_record({exact.bounds(slot), exact.topology(slot)});
          const auto h = reader.locate(traversal::pack(c));
          const DiamondBounds b = reader.bounds(h, kAll);
          const DiamondTopology t = reader.topology(h, kAll);
          if ((std::memcmp(&b, &expected.bounds, sizeof b) != 0 ||
               std::memcmp(&t, &expected.topology, sizeof t) != 0) &&
              ++mismatches < 5)
            ADD_FAILURE() << "record at " << x << " " << y << " " << z << " is not the exact one rounded";
        }
    EXPECT_EQ(mismatches, 0) << "of " << records << " records";
  }
};

// Blocks handed out past the pages already in memory bring the next quarter megabyte in at once
// (detail::prefault), not a page at a time as the decoder writes them.
TEST(BrickPool, ABlockPastThePagesInMemoryBringsTheNextQuarterMegabyteIn) {
  constexpr size_t kPage = 4096, kAhead = size_t{256} << 10, kBlock = 40000;
  BrickPool pool(kBlock);  // 40,000 is a multiple of 64: blocks lie back to back
  const auto resident = [](const char* from, size_t bytes) {
    std::vector<unsigned char> r(bytes / kPage);
    EXPECT_EQ(mincore(const_cast<char*>(from), bytes, r.data()), 0);
    return std::count_if(r.begin(), r.end(), [](unsigned char c) { return (c & 1) != 0; });
  };
  auto* first = static_cast<char*>(pool.allocate());
  ASSERT_EQ(reinterpret_cast<uintptr_t>(first) % kPage, 0u);
  EXPECT_EQ(resident(first, kAhead), static_cast<std::ptrdiff_t>(kAhead / kPage));
  // The blocks that end within those pages bring none; the first past them brings the next 256 KB.
  char* last = first;
  while (last + 2 * kBlock <= first + kAhead) last = static_cast<char*>(pool.allocate());
  last = static_cast<char*>(pool.allocate());
  ASSERT_EQ(last, first + (kAhead / kBlock) * kBlock);
  EXPECT_EQ(resident(first + kAhead, kAhead), static_cast<std::ptrdiff_t>(kAhead / kPage));
}

TEST_F(Store, RoundTripIsExactOnOddDimensionsAndAnyBrickSize) {
  const std::vector<Volume> volumes = {
      testing::crop(generate_noise(70, 3), {30, 19, 23}), testing::crop(generate_noise(70, 4), {41, 9, 70}),
      testing::crop(generate_algebraic(40), {40, 33, 37}), testing::crop(generate_noise(9, 5), {2, 9, 5})};
  for (const Volume& v : volumes)
    for (int bits : {kMinBrickBits, 4, kMaxBrickBits}) {
      ConvertOptions o;
      o.brick_bits = bits;
      SCOPED_TRACE(dims_name(v) + " brick bits " + std::to_string(bits));
      expect_round_trip(v, convert(v, "v" + std::to_string(bits), o), bits);
    }
}

// The header's value range is the data's least and greatest value as the tiles meet them, in the
// store's order: between -0 and 0 (equal, other bits) the first least met. Here the first node,
// which the first row of the first tile starts with, is -0, and every other zero 0.
TEST_F(Store, ValueRangeKeepsTheFirstOfEqualZeros) {
  Volume v = testing::crop(generate_noise(40, 8), {40, 33, 37});
  for (float& f : v.values) f = std::fabs(f) < 0.2f ? 0.0f : std::fabs(f);
  v.values[0] = -0.0f;
  const StoreReader reader(convert(v, "zeros"));
  EXPECT_EQ(reader.header().value_min, 0.0);
  EXPECT_TRUE(std::signbit(reader.header().value_min)) << "the first zero met is -0";
}

// Each real volume as floats, and converted from its raw file in its own type: a uint8 store's
// cache holds its records in narrow words (narrow_bounds), which must read back as the
// very records.
TEST_F(Store, RoundTripIsExactOnRealVolumesAsFloatsAndInTheirOwnType) {
  for (const auto& shared : testing::shared_volumes()) {
    SCOPED_TRACE(shared.name);
    const Volume v = testing::load_shared(shared);
    expect_round_trip(v, convert(v, shared.name));
    if (shared.file.find("uint8") == std::string::npos) continue;  // as floats already
    const std::string own = path(shared.name + "-own.isotope");
    convert_to_store(*open_box_reader({std::string(ISOTOPE_TEST_DATA) + "/" + shared.file, std::nullopt, std::nullopt},
                                      dir_.string()),
                     own, {});
    EXPECT_EQ(BrickCache(StoreReader(own), 1).value_bytes(), 1);
    expect_round_trip(v, own);
  }
}

// A store the page cache does not hold is read the other way (StoreReader's read window: the
// kernel is asked for the window that holds a brick, then the brick is read): the same values and
// records, brick after brick, as from a store just written.
TEST_F(Store, RoundTripIsExactFromAStoreNotInThePageCache) {
  const Volume v = testing::crop(generate_noise(70, 3), {30, 19, 23});
  ConvertOptions o;
  o.brick_bits = kMinBrickBits;  // many bricks: read in windows of several
  const std::string store = convert(v, "cold", o);
  ASSERT_TRUE(testing::drop_from_page_cache(store)) << store << ": fdatasync or posix_fadvise failed";
  if (testing::page_cached(store, kHeaderBytes) == 1)
    GTEST_SKIP() << "the page cache keeps " << store << " (a file system in memory?)";
  expect_round_trip(v, store, kMinBrickBits);
}

// Band 0's records of a uint8 store read for their range and bound alone (an extraction with
// --error bound, the default): computed in the narrow words' integers (PagedVolume),
// they must be the very words of the build in memory, at every node of every brick.
TEST_F(Store, BandZeroRangesAndBoundsOfAUint8StoreAreTheBuildsWithNoOtherField) {
  int volumes = 0;
  for (const auto& shared : testing::shared_volumes()) {
    if (shared.file.find("uint8") == std::string::npos) continue;
    SCOPED_TRACE(shared.name);
    ++volumes;
    const std::string own = path(shared.name + "-own.isotope");
    convert_to_store(*open_box_reader({std::string(ISOTOPE_TEST_DATA) + "/" + shared.file, std::nullopt, std::nullopt},
                                      dir_.string()),
                     own, {});
    ASSERT_EQ(BrickCache(StoreReader(own), 1).value_bytes(), 1);
    const RecordFields none{false, false, false, false};  // ranges and bounds alone
    const Hierarchy loaded = load(own, none);
    const Hierarchy built = Hierarchy::build(testing::load_shared(shared), none, kDefaultBrickBits);
    ASSERT_EQ(loaded.layout().brick_count(), built.layout().brick_count());
    const int64_t nodes = built.layout().brick_nodes();
    const Band& band0 = built.layout().band(0);
    int64_t mismatches = 0, bounded = 0;  // band-0 records with an error bound above 0
    for (int64_t i = 0; i < built.layout().brick_count(); ++i) {
      const BrickView x = loaded.brick(i), y = built.brick(i);
      for (int64_t m = 0; m < nodes; ++m) {
        if (x.bounds[m] != y.bounds[m] && ++mismatches < 5)
          ADD_FAILURE() << "brick " << i << ", node " << m << ": " << std::hex << x.bounds[m] << " against "
                        << y.bounds[m];
        bounded += i < band0.first_brick + band0.brick_count() && bounds_of(y.bounds[m]).bound > 0;
      }
    }
    EXPECT_EQ(mismatches, 0);
    EXPECT_GT(bounded, 1000);
  }
  EXPECT_GE(volumes, 3);
}

// An extraction that reads no simplification weights (mode preserve) computes band 0's topology
// without them and leaves them unset; one that reads them later (simplify), through the same
// cache, computes them then. Each time, every record as a cache that had those fields from the
// start reads it, on a float store and on one of 8-bit codes (values and records held narrow).
TEST_F(Store, BandZeroWeightsLeftOutAreComputedWhenAskedForLater) {
  const Volume v = testing::crop(generate_noise(40, 6), {37, 33, 29});
  ConvertOptions codes;
  codes.quantize_bits = 8;
  for (const auto& [name, options] : {std::pair<std::string, ConvertOptions>{"float", {}}, {"codes", codes}}) {
    SCOPED_TRACE(name);
    const std::string store = convert(v, name, options);
    const StoreReader reader(store);
    BrickCache cache(reader, uint64_t{1} << 34);
    EXPECT_EQ(cache.value_bytes(), name == "codes" ? 1 : 4);
    const PagedVolume volume(cache);
    for (const RecordFields& fields : {RecordFields{true, true, false, true}, kAll}) {
      const Hierarchy loaded = load_hierarchy(volume, fields);
      const Hierarchy fresh = load(store, fields);
      int64_t mismatches = 0;
      for (int64_t i = 0; i < fresh.layout().brick_count(); ++i)
        if (!same_words(loaded, fresh, i, fresh.layout().brick_nodes()) && ++mismatches < 5)
          ADD_FAILURE() << (fields.weights ? "with" : "without") << " weights: brick " << i << " differs";
      EXPECT_EQ(mismatches, 0);
    }
  }
}

// Band 0's records are computed on first read into the brick that holds them, and reading one
// reads its children, in other bricks: each reader must hold the brick it computes into until it has
// read the record back. Here the cache keeps no brick a reader does not hold, and the bricks of
// band 0 that are neighbours in y (32 bricks across) share a reader's pin, so each of those reads
// evicts the brick being computed into unless it is held. Every record must still be the build's,
// for the narrow words of one-byte values and for every field, and every mesh the one a cache that
// evicts nothing gives.
TEST_F(Store, BandZeroRecordsAreTheBuildsWhenTheCacheKeepsOnlyWhatReadersHold) {
  Volume v;
  v.dims = {255, 12, 10};
  v.values.resize(static_cast<size_t>(v.dims[0] * v.dims[1] * v.dims[2]));
  for (int64_t z = 0, i = 0; z < v.dims[2]; ++z)
    for (int64_t y = 0; y < v.dims[1]; ++y)
      for (int64_t x = 0; x < v.dims[0]; ++x, ++i)
        v.values[static_cast<size_t>(i)] =
            static_cast<float>(std::sin(0.21 * static_cast<double>(x)) * std::cos(0.37 * static_cast<double>(y)) +
                               0.05 * static_cast<double>(z));
  ConvertOptions o;
  o.brick_bits = kMinBrickBits;
  o.quantize_bits = 8;
  const std::string store = convert(v, "narrow", o);
  const StoreReader reader(store);
  ASSERT_EQ(reader.layout().band(0).bricks[0], 32);
  const tbb::global_control one(tbb::global_control::max_allowed_parallelism, 1);
  for (const RecordFields& fields : {RecordFields{false, false, false, false}, kAll}) {
    SCOPED_TRACE(fields.topology() ? "every field" : "ranges and bounds");
    BrickCache cache(reader, 1);
    ASSERT_EQ(cache.value_bytes(), 1);
    BrickCacheTesting::keep_only_what_readers_hold(cache);
    const Hierarchy loaded = load_hierarchy(PagedVolume(cache), fields);
    const Hierarchy kept = load(store, fields);                               // a cache that evicts nothing
    EXPECT_GT(cache.stats().bricks_read, 2 * reader.layout().brick_count());  // read again and again
    const int64_t nodes = kept.layout().brick_nodes();
    int64_t mismatches = 0;
    for (int64_t i = 0; i < kept.layout().brick_count(); ++i)
      if (!same_words(loaded, kept, i, nodes) && ++mismatches < 5) ADD_FAILURE() << "brick " << i << " differs";
    EXPECT_EQ(mismatches, 0);
  }
  // And as an extraction reads them (range_bound, and in topology modes every field), each record
  // computed as the walk first reaches it.
  int compared = 0;
  for (const double eps : {0.0, 0.02, 0.1})
    for (const auto mode : {TopologyMode::none, TopologyMode::preserve}) {
      SCOPED_TRACE("eps " + std::to_string(eps) + (mode == TopologyMode::none ? " none" : " preserve"));
      ExtractOptions options;
      options.iso = 0.1f, options.eps = eps, options.topology = mode;
      BrickCache evicting(reader, 1), keeping(reader, uint64_t{1} << 30);
      BrickCacheTesting::keep_only_what_readers_hold(evicting);
      const Mesh a = extract(PagedVolume(evicting), options), b = extract(PagedVolume(keeping), options);
      EXPECT_GT(evicting.stats().bricks_read, keeping.stats().bricks_read);
      ASSERT_GT(b.triangles.size(), 100u);
      ASSERT_EQ(a.positions, b.positions);
      ASSERT_EQ(a.triangles, b.triangles);
      ++compared;
    }
  EXPECT_EQ(compared, 6);
}

// The size target: a store of uint8/uint16 data is at most 1.5x its raw input.
TEST_F(Store, IntegerStoresAreAtMostOneAndAHalfTimesTheirInput) {
  for (const char* name : {"bolt_70x123x66_uint8.raw", "ironProt_68x68x68_uint8.raw", "neghip_66x66x66_uint8.raw"}) {
    const std::string raw = std::string(ISOTOPE_TEST_DATA) + "/" + name, store = path("s.isotope");
    const auto input = open_box_reader({raw, std::nullopt, std::nullopt}, dir_.string());
    convert_to_store(*input, store, {});
    const double ratio =
        static_cast<double>(std::filesystem::file_size(store)) / static_cast<double>(std::filesystem::file_size(raw));
    RecordProperty(name, std::to_string(ratio));
    EXPECT_LE(ratio, 1.5) << name;
    EXPECT_EQ(StoreReader(store).header().source_type, "uint8");
  }
}

// The type of the literals of a section's zstd frame, whose one block must be a compressed block
// (RFC 8878, "Literals_Block_Type"): 0 as they are, 1 one byte repeated, 2 or 3 Huffman-coded.
int literals_type(const std::vector<uint8_t>& section) {
  const uint8_t* f = section.data() + 8;  // after the section's checksum
  const uint8_t descriptor = f[4];        // after the magic number
  const bool single_segment = (descriptor & 0x20) != 0;
  const int content_size_flag = descriptor >> 6, dictionary_flag = descriptor & 3;
  const size_t header = 5 + (single_segment ? 0 : 1) + (dictionary_flag == 3 ? 4 : dictionary_flag) +
                        (content_size_flag == 0 ? (single_segment ? 1 : 0) : size_t{1} << content_size_flag);
  const uint32_t block = f[header] | uint32_t{f[header + 1]} << 8 | uint32_t{f[header + 2]} << 16;
  EXPECT_EQ(block & 1, 1u) << "one block";
  EXPECT_EQ((block >> 1) & 3, 2u) << "a compressed block";
  return f[header + 3] & 3;
}

// A section mostly of floats written as their bit patterns (a float volume stored losslessly)
// keeps its literals as they are, which spares zstd a third of its time there (docs/FORMAT.md,
// "Sections"); one of integers, or of bfloat16 fields, has them Huffman-coded.
TEST(StoreSections, FloatBitPatternsKeepTheirLiteralsAndOtherFieldsHaveThemHuffmanCoded) {
  const StoreLayout layout({40, 40, 40}, 4);
  ASSERT_TRUE(stores_records(layout, 1));
  const auto nodes = static_cast<size_t>(layout.brick_nodes()), records = nodes - nodes / 8;
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> unit(0.0f, 1.0f);
  std::uniform_int_distribution<int> small(0, 15);
  const auto floats = [&](size_t n) {
    std::vector<float> v(n);
    for (float& x : v) x = unit(rng);
    return v;
  };
  const auto bfloats = [&](size_t n) {  // the floats a bfloat16 field's codes stand for
    std::vector<float> v = floats(n);
    for (float& x : v) x = std::bit_cast<float>(std::bit_cast<uint32_t>(x) & 0xffff0000u);
    return v;
  };
  const auto integers = [&](size_t n) {
    std::vector<float> v(n);
    for (float& x : v) x = static_cast<float>(small(rng));
    return v;
  };
  BrickFields noisy;
  noisy.values = floats(nodes);
  for (auto& field : noisy.records) field = bfloats(records);
  noisy.records[BrickFields::bound] = floats(records);
  BrickFields scan = noisy;
  scan.values = integers(nodes);
  scan.records[BrickFields::bound] = integers(records);
  for (const int level : {1, 3, 9}) {
    const auto noisy_sections = encode_brick(layout, 1, noisy, level);
    const auto scan_sections = encode_brick(layout, 1, scan, level);
    EXPECT_EQ(literals_type(noisy_sections[static_cast<size_t>(Section::core)]), 0) << "level " << level;
    EXPECT_GE(literals_type(scan_sections[static_cast<size_t>(Section::core)]), 2) << "level " << level;
    // The bfloat16 fields' sections, whichever the values.
    for (const Section s : {Section::exact, Section::weights, Section::extra})
      EXPECT_GE(literals_type(noisy_sections[static_cast<size_t>(s)]), 2) << "section " << static_cast<int>(s);
    // The others are the frames zstd makes of their bytes at the level with nothing else set:
    // such a section's bytes are those stores held before float sections kept their literals.
    for (const auto* sections : {&scan_sections, &noisy_sections})
      for (int s = 0; s < kSections; ++s) {
        if (sections == &noisy_sections && s == static_cast<int>(Section::core)) continue;
        const std::vector<uint8_t>& bytes = (*sections)[static_cast<size_t>(s)];
        std::vector<uint8_t> raw(ZSTD_getFrameContentSize(bytes.data() + 8, bytes.size() - 8));
        ASSERT_EQ(ZSTD_decompress(raw.data(), raw.size(), bytes.data() + 8, bytes.size() - 8), raw.size());
        std::vector<uint8_t> frame(ZSTD_compressBound(raw.size()));
        frame.resize(ZSTD_compress(frame.data(), frame.size(), raw.data(), raw.size(), level));
        EXPECT_TRUE(std::equal(frame.begin(), frame.end(), bytes.begin() + 8, bytes.end()))
            << "section " << s << ", level " << level;
      }
    // Either way the brick decodes to its fields.
    for (const auto& [fields, sections] : {std::pair{&noisy, &noisy_sections}, std::pair{&scan, &scan_sections}}) {
      std::vector<float> values(nodes);
      std::vector<uint64_t> bounds(nodes), weights(nodes);
      std::vector<uint16_t> surplus(nodes);
      std::vector<uint32_t> exact(nodes), paper(nodes);
      const BrickView view{values.data(), bounds.data(), surplus.data(), exact.data(), paper.data(), weights.data()};
      for (int s = 0; s < kSections; ++s) {
        const auto& bytes = (*sections)[static_cast<size_t>(s)];
        decode_section(layout, 1, static_cast<Section>(s), bytes.data(), bytes.size(), view, values.data(), "brick");
      }
      const BrickFields back = fields_of(layout, 1, view);
      EXPECT_EQ(back.values, fields->values);
      EXPECT_EQ(back.records, fields->records);
    }
  }
}

// Paged (out of core, lazily computed band 0) against the in-memory hierarchy: the same mesh,
// byte for byte, for every mode, indicator and a range of eps.
TEST_F(Store, ExtractionFromStoreEqualsInMemory) {
  struct Case {
    Volume volume;
    std::vector<float> isovalues;
  };
  std::vector<Case> cases = {
      {testing::crop(generate_noise(40, 11), {40, 35, 29}), {-0.3f, 0.0f, 0.25f}},
      {testing::crop(generate_algebraic(40, {5.0 / 32, 3.0 / 32, 0}), {37, 40, 33}), {0.0f, 0.1f}}};
  for (const auto& shared : testing::shared_volumes())
    cases.push_back({testing::load_shared(shared), {shared.isovalues[0], shared.isovalues[1], shared.isovalues[2]}});
  int compared = 0;
  for (Case& c : cases) {
    c.volume.spacing = {1, 1, 1};  // what a raw file carries
    c.volume.origin = {0, 0, 0};
    const Hierarchy memory = Hierarchy::build(c.volume);
    const StoreReader reader(convert(c.volume, "case" + std::to_string(compared)));
    BrickCache cache(reader, uint64_t{1} << 30);
    const PagedVolume stored(cache);
    for (float iso : c.isovalues)
      for (double eps : {0.0, 0.01, 0.1, 1.0, 16.0})
        for (auto mode : {TopologyMode::none, TopologyMode::paper, TopologyMode::preserve, TopologyMode::simplify})
          for (auto error : {ErrorIndicator::bound, ErrorIndicator::surplus}) {
            ExtractOptions o;
            o.iso = iso, o.eps = eps, o.topology = mode, o.error = error;
            if (mode == TopologyMode::simplify) {  // one weight per error indicator, deltas that drop some
              o.weight = error == ErrorIndicator::bound ? SimplificationWeight::interval : SimplificationWeight::size;
              o.delta = error == ErrorIndicator::bound ? 0.05 * eps + 0.01 : 64;
            }
            const Mesh a = extract(memory, o), b = extract(stored, o);
            ASSERT_EQ(a.positions, b.positions) << "iso " << iso << " eps " << eps;
            ASSERT_EQ(a.triangles, b.triangles) << "iso " << iso << " eps " << eps;
            ++compared;
          }
  }
  EXPECT_GE(compared, 300);
}

// A store of some sections (StoreSections: a volume's hierarchy store, with those its extractions
// read) holds those of a store of every section, byte for byte, and no other: an extraction that
// reads no more gets the mesh of a store of every section, in any mode and for either error, and
// one that reads more stops at the missing section instead of taking its records as critical
// nowhere; verify refuses the store.
TEST_F(Store, AStoreOfSomeSectionsServesTheExtractionsThatReadThemAndStopsTheOthers) {
  const Volume v = testing::load_shared(testing::shared_volumes()[1]);  // neghip
  const std::string all = convert(v, "all");
  const StoreReader all_reader(all);
  BrickCache all_cache(all_reader, uint64_t{1} << 30);
  const PagedVolume from_all(all_cache);
  const float iso = testing::shared_volumes()[1].isovalues[0];
  int served = 0, stopped = 0;
  // Those a volume's store is made of: mode none's core; paper's, or none's with the surplus,
  // extra section; preserve's exact one; and with the surplus; and simplify's weights.
  for (const StoreSections& sections :
       {StoreSections{true, false, false, false}, StoreSections{true, false, false, true},
        StoreSections{true, true, false, false}, StoreSections{true, true, false, true},
        StoreSections{true, true, true, false}}) {
    const std::string some = path("some.isotope");
    convert_to_store(VolumeBoxReader(v), some, {}, StoreLife::kept, sections);
    const StoreReader reader(some);
    ASSERT_EQ(reader.layout().brick_count(), all_reader.layout().brick_count());
    int64_t with_records = 0;
    for (int64_t i = 0; i < all_reader.layout().brick_count(); ++i)
      for (size_t s = 0; s < sections.size(); ++s) {
        EXPECT_EQ(reader.entry(i).bytes[s], sections[s] ? all_reader.entry(i).bytes[s] : 0u) << "brick " << i;
        with_records += s == 1 && all_reader.entry(i).bytes[s] > 0;
      }
    EXPECT_GT(with_records, 0);
    BrickCache cache(reader, uint64_t{1} << 30);
    const PagedVolume from_some(cache);
    for (const TopologyMode mode :
         {TopologyMode::none, TopologyMode::paper, TopologyMode::preserve, TopologyMode::simplify})
      for (const ErrorIndicator error : {ErrorIndicator::bound, ErrorIndicator::surplus}) {
        ExtractOptions o;
        o.iso = iso, o.eps = 4, o.topology = mode, o.error = error;
        if (mode == TopologyMode::simplify) o.delta = 8;
        const StoreSections needed = sections_for(fields_for(o));
        bool held = true;
        for (size_t s = 0; s < needed.size(); ++s) held = held && (!needed[s] || sections[s]);
        if (held) {
          const Mesh a = extract(from_all, o), b = extract(from_some, o);
          EXPECT_GT(a.triangles.size(), 100u);
          EXPECT_EQ(a.positions, b.positions) << to_string(mode) << " " << to_string(error);
          EXPECT_EQ(a.triangles, b.triangles) << to_string(mode) << " " << to_string(error);
          ++served;
        } else {
          EXPECT_CONTAINS(io_error_of([&] { extract(from_some, o); }), "a section is missing")
              << to_string(mode) << " " << to_string(error);
          ++stopped;
        }
      }
    EXPECT_CONTAINS(io_error_of([&] { verify_store(some); }), "a section is missing") << "not a store convert writes";
  }
  // none; none and paper, either error; none and preserve; the three, either error; and simplify
  EXPECT_EQ(served, 1 + 4 + 2 + 6 + 3);
  EXPECT_EQ(stopped, 5 * 8 - served);
}

// A chunked, gzip-compressed HDF5 dataset (chunks that do not align with the tiles) converts to
// the same records as the volume in memory.
TEST_F(Store, ChunkedCompressedHdf5Converts) {
  Volume v = testing::load_shared(testing::shared_volumes()[1]);  // neghip, uint8 values
  std::vector<uint16_t> data(v.values.begin(), v.values.end());
  const std::string h5 = path("chunked.h5");
  const hsize_t zyx[3] = {static_cast<hsize_t>(v.dims[2]), static_cast<hsize_t>(v.dims[1]),
                          static_cast<hsize_t>(v.dims[0])};
  const hsize_t chunk[3] = {7, 11, 13};
  const hid_t file = H5Fcreate(h5.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT);
  const hid_t space = H5Screate_simple(3, zyx, nullptr);
  const hid_t dcpl = H5Pcreate(H5P_DATASET_CREATE);
  ASSERT_GE(H5Pset_chunk(dcpl, 3, chunk), 0);
  ASSERT_GE(H5Pset_deflate(dcpl, 6), 0);
  const hid_t ds = H5Dcreate2(file, "/density", H5T_STD_U16LE, space, H5P_DEFAULT, dcpl, H5P_DEFAULT);
  ASSERT_GE(ds, 0);
  ASSERT_GE(H5Dwrite(ds, H5T_NATIVE_UINT16, H5S_ALL, H5S_ALL, H5P_DEFAULT, data.data()), 0);
  H5Dclose(ds);
  H5Pclose(dcpl);
  H5Sclose(space);
  H5Fclose(file);

  const auto input = open_box_reader({h5 + ":/density", std::nullopt, std::nullopt}, dir_.string());
  EXPECT_EQ(input->info().type, "uint16");
  const std::string store = path("chunked.isotope");
  convert_to_store(*input, store, {});
  expect_round_trip(v, store);
  verify_store(store);
}

TEST_F(Store, FileDoesNotDependOnThreadsOrMemoryBudget) {
  const Volume v = testing::crop(generate_noise(70, 8), {70, 45, 39});
  ConvertOptions small;
  small.memory_mb = 1;  // one tile in flight
  const auto a = read_bytes(convert(v, "a", small));
  const auto b = read_bytes(convert(v, "b"));
  testing::Bytes c;
  {
    tbb::global_control one(tbb::global_control::max_allowed_parallelism, 1);
    c = read_bytes(convert(v, "c"));
  }
  EXPECT_FALSE(a.empty());
  EXPECT_TRUE(a == b);
  EXPECT_TRUE(a == c);
}

// A volume file that a quarter of the budget holds is read once and held (HeldBoxReader), a
// larger one box by box: the same store, of float values and of integers held as stored.
TEST_F(Store, AVolumeFileHeldWholeGivesTheStoreOfOneReadBoxByBox) {
  const Volume v = testing::crop(generate_noise(70, 8), {70, 45, 39});
  const std::string floats = path("noise_70x45x39_float32.raw");
  std::ofstream(floats, std::ios::binary)
      .write(reinterpret_cast<const char*>(v.values.data()), static_cast<std::streamsize>(v.values.size() * 4));
  for (const std::string& file : {floats, std::string(ISOTOPE_TEST_DATA) + "/bolt_70x123x66_uint8.raw"}) {
    SCOPED_TRACE(file);
    const auto input = open_box_reader({file, std::nullopt, std::nullopt}, dir_.string());
    ConvertOptions small;
    small.memory_mb = 1;  // a quarter of it under either volume's bytes
    const ConvertStats held =
        convert_to_store(*input, path("held.isotope"), ConvertCall(ConvertOptions{}, RunContext{}));
    const ConvertStats boxes = convert_to_store(*input, path("boxes.isotope"), ConvertCall(small, RunContext{}));
    EXPECT_EQ(held.input_held_bytes, HeldBoxReader::held_bytes(*input));
    EXPECT_GT(held.input_held_bytes, 0u);
    EXPECT_EQ(boxes.input_held_bytes, 0u);
    const testing::Bytes a = read_bytes(path("held.isotope")), b = read_bytes(path("boxes.isotope"));
    EXPECT_FALSE(a.empty());
    EXPECT_TRUE(a == b);
  }
}

// A hand-over in a file (scratch or shared) reads back what its tiles wrote, for any box: whole
// cubes of kHandoverBlock^3 entries and boxes cut off their grid, the grid's thin last cubes, and
// boxes in memory with room between their rows and planes.
TEST_F(Store, AHandoverInAFileReadsBackAnyBoxOfWhatItsTilesWrote) {
  const Box3 nodes{37, 21, 50};  // cubes of 16: 3 x 2 x 4, the last of 5, 5 and 2 entries
  std::mt19937 rng(7);
  const auto n = static_cast<size_t>(nodes[0] * nodes[1] * nodes[2]);
  std::vector<float> values(n);
  std::vector<Record> children(n);
  for (float& v : values) v = std::uniform_real_distribution<float>(-5, 5)(rng);
  std::vector<uint8_t> noise(n * sizeof(Record));
  for (uint8_t& b : noise) b = static_cast<uint8_t>(rng());
  std::memcpy(static_cast<void*>(children.data()), noise.data(), noise.size());
  auto at = [&](int64_t x, int64_t y, int64_t z) { return static_cast<size_t>((z * nodes[1] + y) * nodes[0] + x); };
  // Tiles' parts: whole cubes below z = 16, slabs of a cube's planes (3 at a time) below 32,
  // boxes of 7 x 5 x 3 cut off the cubes above.
  std::vector<std::pair<Box3, Box3>> parts;
  for (int64_t z = 0; z < nodes[2];) {
    const Box3 step = z < 16 ? Box3{16, 16, 16} : z < 32 ? Box3{16, 16, 3} : Box3{7, 5, 3};
    const int64_t z1 = std::min({z + step[2], nodes[2], z < 32 ? (z / 16 + 1) * int64_t{16} : nodes[2]});
    for (int64_t y = 0; y < nodes[1]; y += step[1])
      for (int64_t x = 0; x < nodes[0]; x += step[0])
        parts.push_back({{x, y, z}, {std::min(x + step[0], nodes[0]), std::min(y + step[1], nodes[1]), z1}});
    z = z1;
  }
  std::vector<std::unique_ptr<BandHandover>> files;
  files.push_back(std::make_unique<ScratchHandover>(dir_.string(), nodes));
  files.push_back(std::make_unique<SharedHandover>(path("shared.handover"), SharedFile::Mode::create, nodes));
  for (auto& file : files) {
    for (const auto& [lo, hi] : parts)
      file->write_box(lo, hi, &values[at(lo[0], lo[1], lo[2])], &children[at(lo[0], lo[1], lo[2])], nodes[0],
                      nodes[0] * nodes[1]);
    for (int trial = 0; trial < 200; ++trial) {
      Box3 lo, hi;
      for (int a = 0; a < 3; ++a) {
        lo[a] = std::uniform_int_distribution<int64_t>(0, nodes[a] - 1)(rng);
        hi[a] = std::uniform_int_distribution<int64_t>(lo[a] + 1, nodes[a])(rng);
      }
      const int64_t row = hi[0] - lo[0] + 3, plane = row * (hi[1] - lo[1] + 2);
      const auto room = static_cast<size_t>(plane * (hi[2] - lo[2]));
      std::vector<float> v(room, -1.0f);
      std::vector<Record> r(room);
      file->read_values(lo, hi, v.data(), row, plane);
      file->read_children(lo, hi, r.data(), row, plane);
      for (int64_t z = lo[2]; z < hi[2]; ++z)
        for (int64_t y = lo[1]; y < hi[1]; ++y)
          for (int64_t x = lo[0]; x < hi[0]; ++x) {
            const auto i = static_cast<size_t>((z - lo[2]) * plane + (y - lo[1]) * row + (x - lo[0]));
            ASSERT_EQ(v[i], values[at(x, y, z)]) << x << "," << y << "," << z;
            ASSERT_EQ(std::memcmp(&r[i], &children[at(x, y, z)], sizeof(Record)), 0) << x << "," << y << "," << z;
          }
      // Nothing written beyond the box's rows.
      for (int64_t z = lo[2]; z < hi[2]; ++z)
        for (int64_t y = lo[1]; y < hi[1]; ++y)
          ASSERT_EQ(v[static_cast<size_t>((z - lo[2]) * plane + (y - lo[1]) * row + (hi[0] - lo[0]))], -1.0f);
    }
  }
}

// A tile's part of whole cubes is written in a call a cube and read back in a call a cube; a box
// cut off the cubes' grid takes a call a row to write, and still one a cube to read.
TEST(HandoverFile, WholeCubesTakeACallEach) {
  struct CountingFile {
    void write(const void*, size_t, uint64_t) const { ++writes; }
    void read(void*, size_t, uint64_t) const { ++reads; }
    mutable int64_t writes = 0, reads = 0;
  };
  const Box3 nodes{40, 40, 40};
  const BlockedEntries blocks(nodes);
  std::vector<float> v(static_cast<size_t>(40 * 40 * 40));
  CountingFile file;
  blocks.write(file, 0, {0, 0, 16}, {32, 32, 33}, v.data(), 40, 40 * 40);  // 2 x 2 x 2 cubes, the last one plane
  EXPECT_EQ(file.writes, 8);
  blocks.write(file, 0, {32, 32, 32}, {40, 40, 40}, v.data(), 40, 40 * 40);  // the grid's last cube, whole
  EXPECT_EQ(file.writes, 9);
  blocks.write(file, 0, {3, 0, 0}, {16, 16, 2}, v.data(), 40, 40 * 40);  // cut off: 16 rows of 2 planes
  EXPECT_EQ(file.writes, 9 + 32);
  blocks.read(file, 0, {15, 15, 15}, {17, 17, 17}, v.data(), 40, 40 * 40);
  EXPECT_EQ(file.reads, 8);
}

// Where band 1's hand-over would be a scratch file (at 128 MB, 97 x 96 x 92 x 48 bytes is beyond a
// quarter of the budget), bands 0 and 1 are built in one pass and band 1's bricks held aside
// until band 0's last is written: the same file as band by band (at 1024 MB, in memory). 191
// nodes along x: band 0 has 192 (records reach one node beyond the data), band 1 97, whose last
// brick comes with band 0's last tile, out of Morton order.
TEST_F(Store, AFileBuiltWithTwoBandsInOnePassIsTheFileBuiltBandByBand) {
  // Fused tiles of 64 nodes (about 24 MB) must fit one a thread in three quarters of the budget:
  // two threads, so that they do in 128 MB on any machine.
  const tbb::global_control two(tbb::global_control::max_allowed_parallelism, 2);
  const Volume v = testing::crop(generate_noise(192, 9), {191, 190, 181});
  auto store = [&](const std::string& name, int memory_mb, int expect_beside) {
    ConvertOptions o;
    o.memory_mb = memory_mb;
    const std::string path = (dir_ / (name + ".isotope")).string();
    EXPECT_EQ(isotope::convert(v, path, o).bands_built_beside, expect_beside) << name;
    return read_bytes(path);
  };
  const auto band_by_band = store("apart", 1024, 0);
  const auto fused = store("fused", 128, 1);
  testing::Bytes one_thread;
  {
    tbb::global_control one(tbb::global_control::max_allowed_parallelism, 1);
    one_thread = store("fused1", 128, 1);
  }
  EXPECT_FALSE(fused.empty());
  EXPECT_TRUE(fused == band_by_band);
  EXPECT_TRUE(one_thread == band_by_band);
  verify_store((dir_ / "fused.isotope").string());
}

TEST_F(Store, CancelledConvertLeavesNothing) {
  const Volume v = generate_noise(65, 2);
  std::atomic<bool> cancel{false};
  ConvertOptions o;
  o.memory_mb = 1;
  RunContext run;
  run.progress = [&](double f) {
    if (f > 0.3) cancel = true;
  };
  run.cancel = &cancel;
  const auto before = entries();
  EXPECT_CONTAINS(io_error_of([&] { convert(v, "cancelled", o, run); }), "interrupted");
  auto after = entries();
  after.erase(std::remove(after.begin(), after.end(), "cancelled_65x65x65_float32.raw"), after.end());
  EXPECT_EQ(after, before);
}

// Quantized float data: the store holds the records of the quantized field (codes) exactly; the
// traversal adds half a code step to every error, and extraction maps the isovalue onto codes.
TEST_F(Store, QuantizedStoreIsExactForTheQuantizedField) {
  Volume v = testing::load_shared(testing::shared_volumes()[2]);  // hydrogen, float32
  ASSERT_EQ(v.dims[0], 64);
  for (int bits : {8, 16}) {
    ConvertOptions o;
    o.quantize_bits = bits;
    const std::string store = convert(v, "q" + std::to_string(bits), o);
    const StoreReader reader(store);
    const StoreHeader h = reader.header();
    EXPECT_EQ(h.quantize_bits, bits);
    Volume codes = v;
    for (float& x : codes.values)
      x = std::clamp(std::nearbyint(static_cast<float>((x - h.value_offset) / h.value_scale)), 0.0f,
                     static_cast<float>((1 << bits) - 1));
    expect_round_trip(codes, store);
    BrickCache cache(reader, uint64_t{1} << 30);
    const PagedVolume stored(cache);
    const Hierarchy memory = Hierarchy::build(codes);
    for (float iso : {0.05f, 0.1f, 0.3f})
      for (double eps : {0.0, 0.02, 0.2}) {
        ExtractOptions physical, in_codes;
        physical.iso = iso, physical.eps = eps;
        in_codes.iso = static_cast<float>((iso - h.value_offset) / h.value_scale);
        // Codes are integers, errors half-integers: err + 1/2 < eps exactly when err < eps - 1/2.
        in_codes.eps = std::max(0.0, eps / h.value_scale - kQuantizationError);
        const Mesh a = extract(stored, physical), b = extract(memory, in_codes);
        EXPECT_EQ(a.triangles, b.triangles) << bits << " bits, iso " << iso << " eps " << eps;
        EXPECT_EQ(a.positions, b.positions);
        // Weights in codes: |X| scales with the values, |X| times a gradient with their square.
        const double scale = h.value_scale;
        for (auto [weight, delta, per_code] : {std::tuple{SimplificationWeight::interval, 0.01, scale},
                                               std::tuple{SimplificationWeight::gradient, 1e-4, scale * scale},
                                               std::tuple{SimplificationWeight::size, 100.0, 1.0}}) {
          physical.topology = in_codes.topology = TopologyMode::simplify;
          physical.weight = in_codes.weight = weight;
          physical.delta = delta;
          in_codes.delta = delta / per_code;
          EXPECT_EQ(extract(stored, physical).triangles, extract(memory, in_codes).triangles)
              << bits << " bits, iso " << iso << " eps " << eps << " weight " << to_string(weight);
        }
        physical.topology = in_codes.topology = TopologyMode::preserve;
        physical.delta = in_codes.delta = 0;
      }
  }
  // Smaller than lossless: 8 bits well below, 16 bits below.
  const auto lossless = std::filesystem::file_size(convert(v, "lossless"));
  EXPECT_LT(std::filesystem::file_size(path("q8.isotope")) * 4, lossless);
  EXPECT_LT(std::filesystem::file_size(path("q16.isotope")), lossless);
}

TEST_F(Store, QuantizeRefusesIntegerData) {
  Volume v = testing::load_shared(testing::shared_volumes()[0]);
  ConvertOptions o;
  o.quantize_bits = 8;
  // An integer volume read back as float32 raw is float data; mark it integer through a uint8 file.
  const std::string raw = path("i_" + dims_name(v) + "_uint8.raw");
  testing::Bytes bytes(v.values.begin(), v.values.end());
  testing::write_file(raw, "", bytes);
  const auto input = open_box_reader({raw, std::nullopt, std::nullopt}, dir_.string());
  try {
    convert_to_store(*input, path("i.isotope"), o);
    ADD_FAILURE() << "quantizing integer data was not refused";
  } catch (const OptionError& e) {  // the command's usage error: --quantize does not apply
    EXPECT_EQ(e.option, "quantize");
    EXPECT_CONTAINS(e.message, "integer data");
  }
  EXPECT_FALSE(std::filesystem::exists(path("i.isotope")));
}

// A coarse extraction reads a fraction of the store (the bands it stops in, the sections its mode
// reads) and the paged cache holds no more than it decoded; eps 0 reads band 0 where the surface is.
TEST_F(Store, CoarseExtractionReadsWhatItStopsIn) {
  const Volume v = generate_algebraic(129);
  const std::string store = convert(v, "alg");
  const StoreReader reader(store);
  const uint64_t bricks_bytes = reader.brick_area_end() - kHeaderBytes;
  auto bytes_read = [&](const ExtractOptions& o) {
    BrickCache cache(reader, uint64_t{1} << 30);
    const PagedVolume paged(cache);
    extract(paged, o);
    return cache.stats().bytes_read;
  };
  ExtractOptions coarse;
  coarse.eps = 0.05;  // about 1% of the full triangles
  coarse.topology = TopologyMode::none;
  ExtractOptions preserve = coarse;
  preserve.topology = TopologyMode::preserve;
  const uint64_t none_bytes = bytes_read(coarse), preserve_bytes = bytes_read(preserve);
  ExtractOptions full;
  const uint64_t full_bytes = bytes_read(full);
  RecordProperty("coarse_none_share",
                 std::to_string(static_cast<double>(none_bytes) / static_cast<double>(bricks_bytes)));
  EXPECT_LT(none_bytes * 10, bricks_bytes) << "a coarse none extraction reads under a tenth of the store";
  EXPECT_LT(none_bytes, preserve_bytes) << "none reads no critical interval";
  EXPECT_LT(none_bytes, full_bytes);
}

// Corruption: every byte of a store is covered by a checksum, so any change is caught.
class StoreCorruption : public Store {
 protected:
  void SetUp() override {
    Store::SetUp();
    ConvertOptions o;
    o.brick_bits = kMinBrickBits;  // many small bricks
    good_ = read_bytes(convert(testing::crop(generate_noise(40, 21), {21, 17, 19}), "good", o));
    bad_ = path("bad.isotope");
  }
  // What verify says about `bytes`, or "" when it accepts them.
  std::string verify_message(const testing::Bytes& bytes) {
    testing::write_file(bad_, "", bytes);
    return message_of([&] { verify_store(bad_); });
  }
  // What reading the whole store as an extraction does says, or "" when it succeeds.
  std::string load_message(const testing::Bytes& bytes) {
    testing::write_file(bad_, "", bytes);
    return message_of([&] { load(bad_); });
  }
  testing::Bytes good_;
  std::string bad_;
};

TEST_F(StoreCorruption, GoodStoreVerifies) {
  EXPECT_EQ(verify_message(good_), "");
  EXPECT_EQ(load_message(good_), "");
}

// Each section of each brick: a flipped byte is named by verify and by the extraction's reads.
TEST_F(StoreCorruption, FlippedByteInEverySectionOfEveryBrickIsNamed) {
  testing::write_file(bad_, "", good_);
  const StoreReader reader(bad_);
  std::mt19937 rng(5);
  int sections = 0;
  for (int64_t i = 0; i < reader.layout().brick_count(); ++i) {
    const BrickEntry e = reader.entry(i);
    for (int s = 0; s < kSections; ++s) {
      if (e.bytes[static_cast<size_t>(s)] == 0) continue;
      auto bytes = good_;
      bytes[e.section_offset(static_cast<Section>(s)) + rng() % e.bytes[static_cast<size_t>(s)]] ^=
          static_cast<uint8_t>(1 + rng() % 255);
      const std::string name = "brick " + std::to_string(i) + " ";
      EXPECT_CONTAINS(verify_message(bytes), name);
      EXPECT_CONTAINS(load_message(bytes), name);
      ++sections;
    }
  }
  EXPECT_GT(sections, reader.layout().brick_count());
}

// With several bad bricks, verify names the first in directory order, on any number of threads:
// the same store gives the same message every time.
TEST_F(StoreCorruption, FirstBadBrickIsNamedWhateverTheThreads) {
  testing::write_file(bad_, "", good_);
  const StoreReader reader(bad_);
  const int64_t count = reader.layout().brick_count();
  ASSERT_GT(count, 8);
  auto bytes = good_;
  // The first at the end of the first half, which a second thread starting on the second half
  // would pass last.
  const int64_t first = count / 2 - 1;
  for (const int64_t i : {first, first + 1, count - 1})
    bytes[reader.entry(i).offset + reader.entry(i).bytes[0] / 2] ^= 0x5a;
  for (const size_t threads : {size_t{1}, size_t{2}, size_t{8}}) {
    const tbb::global_control limit(tbb::global_control::max_allowed_parallelism, threads);
    for (int run = 0; run < 10; ++run)
      EXPECT_CONTAINS(verify_message(bytes), "brick " + std::to_string(first) + " ") << threads << " threads";
  }
}

TEST_F(StoreCorruption, TruncationWrongMagicAndVersion) {
  for (size_t size : {size_t{0}, size_t{7}, size_t{100}, kHeaderBytes - 1, kHeaderBytes, kHeaderBytes + 1,
                      good_.size() / 2, good_.size() - 1}) {
    auto bytes = good_;
    bytes.resize(size);
    const std::string m = verify_message(bytes);
    EXPECT_TRUE(m.find("truncated") != std::string::npos || m.find("not an isotope store") != std::string::npos) << m;
  }
  auto magic = good_;
  magic[0] = 'X';
  EXPECT_CONTAINS(verify_message(magic), "not an isotope store");
  auto version = good_;
  version[8] = 5;
  EXPECT_CONTAINS(verify_message(version), "version 5 is not supported");
  EXPECT_EQ(verify_message(version).find("convert the volume again"), std::string::npos);
  for (int older : {2, 3}) {  // before compact records; before the clamped errors at the box: says what to do
    version[8] = static_cast<uint8_t>(older);
    EXPECT_CONTAINS(verify_message(version), "version " + std::to_string(older) + " is not supported");
    EXPECT_CONTAINS(verify_message(version), "convert the volume again");
  }
  auto header = good_;
  header[40] ^= 1;
  EXPECT_CONTAINS(verify_message(header), "header checksum");
  auto directory = good_;
  directory[good_.size() - 10] ^= 1;
  EXPECT_CONTAINS(verify_message(directory), "directory checksum");
  auto longer = good_;
  longer.push_back(0);
  EXPECT_CONTAINS(verify_message(longer), "unexpected bytes");
}

// A store whose checksums are all right but whose content is wrong: brick `index` rewritten with
// `edit` applied to its decoded arrays, every offset, checksum and directory redone.
void rewrite_brick(const std::string& path, int64_t index, const std::function<void(const BrickView&)>& edit) {
  const StoreReader store(path);
  const testing::Bytes file = read_bytes(path);
  const StoreLayout& layout = store.layout();
  const auto n = static_cast<size_t>(layout.brick_nodes());
  std::vector<float> values(n);
  std::vector<uint64_t> bounds(n);
  std::vector<uint16_t> surplus(n);
  std::vector<uint32_t> exact(n), paper(n);
  std::vector<uint64_t> weights(n);
  const BrickView view{values.data(), bounds.data(), surplus.data(), exact.data(), paper.data(), weights.data()};
  store.read_brick(index, {true, true, true, true}, view, values.data());
  edit(view);
  const auto [band, b] = store.locate_brick(index);
  const auto sections = encode_brick(layout, band, fields_of(layout, band, view), store.header().zstd_level);
  std::vector<BrickEntry> dir(static_cast<size_t>(layout.brick_count()));
  for (int64_t i = 0; i < layout.brick_count(); ++i) dir[static_cast<size_t>(i)] = store.entry(i);
  std::vector<int64_t> order(dir.size());
  for (size_t i = 0; i < order.size(); ++i) order[i] = static_cast<int64_t>(i);
  std::sort(order.begin(), order.end(), [&](int64_t x, int64_t y) {
    return dir[static_cast<size_t>(x)].offset < dir[static_cast<size_t>(y)].offset;
  });
  testing::Bytes out(file.begin(), file.begin() + kHeaderBytes);
  for (int64_t i : order) {
    BrickEntry& e = dir[static_cast<size_t>(i)];
    const auto first = file.begin() + static_cast<std::ptrdiff_t>(e.offset);
    const testing::Bytes old(first, first + static_cast<std::ptrdiff_t>(e.total()));
    e.offset = out.size();
    if (i != index) {
      out.insert(out.end(), old.begin(), old.end());
      continue;
    }
    for (int s = 0; s < kSections; ++s) {
      const std::vector<uint8_t>& bytes = sections[static_cast<size_t>(s)];
      e.bytes[static_cast<size_t>(s)] = static_cast<uint32_t>(bytes.size());
      out.insert(out.end(), bytes.begin(), bytes.end());
    }
  }
  StoreHeader h = store.header();
  for (const Band& band_j : layout.bands()) {
    const std::vector<BrickEntry> mine(dir.begin() + band_j.first_brick,
                                       dir.begin() + band_j.first_brick + band_j.brick_count());
    const std::vector<uint8_t> directory = encode_directory(mine);
    BandDirectory& d = h.bands[static_cast<size_t>(band_j.scale)];
    d.offset = out.size();
    d.checksum = store_checksum(directory.data(), directory.size());
    out.insert(out.end(), directory.begin(), directory.end());
  }
  const auto header = encode_header(h);
  std::copy(header.begin(), header.end(), out.begin());
  testing::write_file(path, "", out);
}

// verify also checks what no checksum can: that coarser bands repeat the finer bands' values, and
// that each record's range holds its node's value.
TEST_F(StoreCorruption, ConsistentChecksumsButContradictoryBricksAreCaught) {
  testing::write_file(bad_, "", good_);
  const StoreLayout layout = StoreReader(bad_).layout();
  // Node (2, 0, 0) of band 1: Morton 8, all-even, so no record of its own bounds it in this band.
  rewrite_brick(bad_, layout.brick_index(1, {0, 0, 0}),
                [](const BrickView& b) { const_cast<float*>(b.values)[8] += 1; });
  EXPECT_EQ(load_message(read_bytes(bad_)), "") << "the edit must keep the store readable";
  EXPECT_CONTAINS(verify_message(read_bytes(bad_)), "differs from band 0");

  testing::write_file(bad_, "", good_);
  // Node (1, 0, 0) of band 1 (Morton 1): a record whose range lies above its value.
  rewrite_brick(bad_, layout.brick_index(1, {0, 0, 0}), [](const BrickView& b) {
    PackedBounds p = bounds_of(b.bounds[1]);
    p.lo = p.hi = bf16_up(b.values[1] + 1);
    b.bounds[1] = bounds_word(p);
  });
  EXPECT_CONTAINS(verify_message(read_bytes(bad_)), "value outside its record's range");
}

// A uint8 store's cache holds each record's range and bound in 32 bits (narrow_bounds
// packs them). A record those bits cannot hold exactly, under valid checksums, is named as a
// corrupt brick by the read that finds it, never rounded into another record.
TEST_F(StoreCorruption, ARecordNarrowWordsCannotHoldIsACorruptBrickOfAUint8Store) {
  const std::string good = path("neghip.isotope");
  convert_to_store(
      *open_box_reader({std::string(ISOTOPE_TEST_DATA) + "/neghip_66x66x66_uint8.raw", std::nullopt, std::nullopt},
                       dir_.string()),
      good, {});
  const StoreLayout layout = StoreReader(good).layout();
  const int64_t index = layout.brick_index(1, {0, 0, 0}), other = layout.brick_index(2, {0, 0, 0});
  struct Case {
    const char* name;
    std::function<void(PackedBounds&)> edit;
  };
  const std::vector<Case> cases = {
      {"a bound between halves", [](PackedBounds& p) { p.bound = 2.25f; }},
      {"a negative bound", [](PackedBounds& p) { p.bound = -1; }},
      {"a bound of -0", [](PackedBounds& p) { p.bound = -0.0f; }},
      {"a bound of NaN", [](PackedBounds& p) { p.bound = std::numeric_limits<float>::quiet_NaN(); }},
      {"a bound beyond 32767", [](PackedBounds& p) { p.bound = 32767.5f; }},
      {"a range from -0", [](PackedBounds& p) { p.lo = 0x8000; }},
      {"a fraction in the range", [](PackedBounds& p) { p.lo = bf16_down(0.5f), p.hi = std::max(p.hi, bf16_up(1)); }},
      {"a range beyond 255", [](PackedBounds& p) { p.hi = bf16_up(256); }},
      {"a range upside down", [](PackedBounds& p) { p.lo = bf16_down(9), p.hi = bf16_down(8); }},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.name);
    testing::write_file(bad_, "", read_bytes(good));
    // Node (1, 0, 0) of band 1 (Morton 1): a record of its own.
    rewrite_brick(bad_, index, [&](const BrickView& b) {
      PackedBounds p = bounds_of(b.bounds[1]);
      c.edit(p);
      b.bounds[1] = bounds_word(p);
    });
    const StoreReader store(bad_);
    BrickCache cache(store, uint64_t{1} << 30);
    ASSERT_EQ(cache.value_bytes(), 1);
    const std::string message = message_of([&] { cache.get(index); });
    EXPECT_NE(message.find("band 1"), std::string::npos) << message;
    EXPECT_NE(message.find("holds a record whose range is not of integers of 0..255 in order, or whose bound is "
                           "not a multiple of a half up to 32767 nor +inf (corrupt brick)"),
              std::string::npos)
        << message;
    EXPECT_EQ(message_of([&] { cache.get(other); }), "") << "a brick without the record reads";
    // verify refuses what the extraction refuses (a negative or NaN bound by its own check first).
    EXPECT_CONTAINS(verify_message(read_bytes(bad_)), "(band 1, brick 0 0 0): ");
  }
}

// Header fields edited and the header's checksum redone: the checksum holds, the content cannot
// be. Every reader path (the extraction's, verify's) refuses each with a message naming it.
TEST_F(StoreCorruption, HeaderFieldsOutOfTheirRangesAreRefusedUnderAValidChecksum) {
  const StoreHeader good = StoreReader([&] {
                             testing::write_file(bad_, "", good_);
                             return bad_;
                           }())
                               .header();
  const double nan = std::numeric_limits<double>::quiet_NaN(), inf = std::numeric_limits<double>::infinity();
  const std::vector<std::pair<std::function<void(StoreHeader&)>, std::string>> edits = {
      {[&](StoreHeader& h) { h.spacing[1] = nan; }, "spacing"},
      {[&](StoreHeader& h) { h.spacing[0] = 0; }, "spacing"},
      {[&](StoreHeader& h) { h.spacing[2] = -1; }, "spacing"},
      {[&](StoreHeader& h) { h.spacing[2] = inf; }, "spacing"},
      {[&](StoreHeader& h) { h.origin[0] = nan; }, "origin"},
      {[&](StoreHeader& h) { h.origin[1] = -inf; }, "origin"},
      {[&](StoreHeader& h) { h.value_scale = 2; }, "value mapping"},  // lossless: the identity only
      {[&](StoreHeader& h) { h.value_offset = 1; }, "value mapping"},
      {[&](StoreHeader& h) { h.brick_bits = 8; }, "brick size"},  // 712 MB a brick in format 2
      {[&](StoreHeader& h) { h.brick_bits = 2; }, "brick size"},
      {[&](StoreHeader& h) { h.dims[0] = int64_t{1} << 40; }, "dimensions"},
      {[&](StoreHeader& h) { h.value_min = nan; }, "value range"},
  };
  for (const auto& [edit, named] : edits) {
    StoreHeader h = good;
    edit(h);
    auto bytes = good_;
    const auto header = encode_header(h);
    std::copy(header.begin(), header.end(), bytes.begin());
    EXPECT_CONTAINS(load_message(bytes), named);
    EXPECT_CONTAINS(verify_message(bytes), named);
  }
  // A reserved byte set, the checksum redone.
  auto reserved = good_;
  reserved[kHeaderBytes - 100] = 1;
  const uint64_t sum = store_checksum(reserved.data(), kHeaderBytes - 8);
  std::memcpy(reserved.data() + kHeaderBytes - 8, &sum, sizeof sum);
  EXPECT_CONTAINS(load_message(reserved), "reserved bytes");
  EXPECT_CONTAINS(verify_message(reserved), "reserved bytes");
}

// A directory entry pointing at another brick's bytes (a duplicate, so every brick checksum holds),
// with the directory's and the header's checksums redone: the extraction's reads refuse it, not
// only verify.
TEST_F(StoreCorruption, DirectoryEntriesThatOverlapAreCaughtByTheExtractionToo) {
  testing::write_file(bad_, "", good_);
  testing::Bytes file = read_bytes(bad_);
  {
    const StoreReader store(bad_);
    StoreHeader h = store.header();
    const Band& band0 = store.layout().band(0);
    ASSERT_GE(band0.brick_count(), 2);
    std::vector<BrickEntry> dir(static_cast<size_t>(band0.brick_count()));
    for (int64_t i = 0; i < band0.brick_count(); ++i) dir[static_cast<size_t>(i)] = store.entry(band0.first_brick + i);
    dir[1] = dir[0];
    const std::vector<uint8_t> directory = encode_directory(dir);
    BandDirectory& d = h.bands[0];
    std::copy(directory.begin(), directory.end(), file.begin() + static_cast<std::ptrdiff_t>(d.offset));
    d.checksum = store_checksum(directory.data(), directory.size());
    const auto header = encode_header(h);
    std::copy(header.begin(), header.end(), file.begin());
  }
  EXPECT_CONTAINS(load_message(file), "overlaps entry");
  EXPECT_CONTAINS(verify_message(file), "overlaps entry");
}

// The directory's tiling check (check_directory) against the plain sort of the offsets it once
// made: on directories that tile their run in the writer's Morton order (the walk that needs no
// sort) or in a shuffled order, with sizes from a few bytes to far more than the average, it
// accepts the good ones and names the same first fault in the bad ones (an entry moved onto
// another, by a byte, or across the run; two entries of one offset).
TEST(StoreDirectory, TheTilingCheckNamesWhatTheSortOfOffsetsNames) {
  auto sorted_fault = [](const std::vector<BrickEntry>& entries) -> std::string {
    std::vector<std::pair<uint64_t, uint32_t>> order;
    for (size_t i = 0; i < entries.size(); ++i)
      if (entries[i].total() != 0) order.emplace_back(entries[i].offset, static_cast<uint32_t>(i));
    std::sort(order.begin(), order.end());
    for (size_t i = 1; i < order.size(); ++i) {
      const BrickEntry& before = entries[order[i - 1].second];
      const uint64_t end = before.offset + before.total();
      if (order[i].first != end)
        return "directory entry " + std::to_string(order[i].second) +
               (order[i].first < end ? " overlaps entry " : " leaves a gap after entry ") +
               std::to_string(order[i - 1].second);
    }
    return "";
  };
  auto checked_fault = [](const std::vector<BrickEntry>& entries, const Box3& grid, uint64_t area_end) -> std::string {
    BandDirectory d;
    d.checksum = store_checksum(entries.data(), entries.size() * sizeof(BrickEntry));
    try {
      check_directory(entries, grid, d, area_end, "s.isotope");
    } catch (const IoError& e) {
      const std::string m = e.what();
      const std::string prefix = "s.isotope: ", suffix = " (corrupt directory)";
      EXPECT_EQ(m.rfind(prefix, 0), 0u) << m;
      EXPECT_GE(m.size(), prefix.size() + suffix.size()) << m;
      return m.substr(prefix.size(), m.size() - prefix.size() - suffix.size());
    }
    return "";
  };
  std::mt19937_64 rng(29);
  int faults = 0, tried = 0, in_morton = 0;
  for (int round = 0; round < 60; ++round) {
    // A band's grid of bricks, not always a cube nor a power of two a side.
    const Box3 grid{static_cast<int64_t>(1 + rng() % 16), static_cast<int64_t>(1 + rng() % 16),
                    static_cast<int64_t>(1 + rng() % 12)};
    const auto n = static_cast<size_t>(grid[0] * grid[1] * grid[2]);
    std::vector<BrickEntry> entries(n);
    std::vector<size_t> file_order;
    if (round % 2 == 0) {
      for (const Box3& b : in_morton_order(grid))
        file_order.push_back(static_cast<size_t>((b[2] * grid[1] + b[1]) * grid[0] + b[0]));
      ++in_morton;
    } else {
      for (size_t i = 0; i < n; ++i) file_order.push_back(i);
      std::shuffle(file_order.begin(), file_order.end(), rng);
    }
    uint64_t at = kHeaderBytes;
    for (size_t i : file_order) {
      BrickEntry& e = entries[i];
      e.offset = at;
      if (rng() % 10 == 0) continue;  // a brick of no bytes
      // Mostly small, now and then one far larger than the rest: the spans fill unevenly.
      e.bytes[0] = static_cast<uint32_t>(kChecksumBytes + 1 + rng() % (rng() % 20 == 0 ? 1000000 : 300));
      if (rng() % 2) e.bytes[1] = static_cast<uint32_t>(kChecksumBytes + 1 + rng() % 100);
      at += e.total();
    }
    const uint64_t area_end = at + 2000000;  // room for any entry moved past the run
    ++tried;
    EXPECT_EQ(checked_fault(entries, grid, area_end), "") << "round " << round;
    EXPECT_EQ(sorted_fault(entries), "") << "round " << round;
    if (n < 3) continue;
    const size_t a = rng() % n, b = rng() % n;
    if (a == b || entries[a].total() == 0 || entries[b].total() == 0) continue;
    std::vector<std::vector<BrickEntry>> bad(4, entries);
    bad[0][a].offset = entries[b].offset;  // onto another brick
    bad[1][a].offset += 1;                 // a byte along
    bad[2][a].offset = at;                 // past the end of the run
    bad[3][a] = entries[b];                // a copy of another entry
    for (size_t k = 0; k < bad.size(); ++k) {
      const std::string want = sorted_fault(bad[k]);
      // Moved past the end of the run, the run's first brick still tiles it: both accept that.
      if (k != 2) {
        EXPECT_NE(want, "") << "round " << round;
      }
      EXPECT_EQ(checked_fault(bad[k], grid, area_end), want) << "round " << round;
      faults += !want.empty();
    }
  }
  EXPECT_EQ(tried, 60);
  EXPECT_EQ(in_morton, 30);
  EXPECT_GT(faults, 100);
}

// Randomized: flips, overwrites, truncations and insertions anywhere. Each one must be caught
// (an IoError, never a crash), by verify and by the extraction's reads.
TEST_F(StoreCorruption, RandomizedCorruptionIsAlwaysCaught) {
  std::mt19937 rng(1234);
  constexpr int kIterations = 400;
  int caught = 0;
  for (int it = 0; it < kIterations; ++it) {
    auto bytes = good_;
    switch (rng() % 4) {
      case 0: bytes[rng() % bytes.size()] ^= static_cast<uint8_t>(1 + rng() % 255); break;
      case 1: {
        const size_t at = rng() % bytes.size(), n = std::min<size_t>(1 + rng() % 64, bytes.size() - at);
        for (size_t i = 0; i < n; ++i) bytes[at + i] = static_cast<uint8_t>(rng());
        if (bytes == good_) continue;
        break;
      }
      case 2: bytes.resize(rng() % bytes.size()); break;
      default:
        bytes.insert(bytes.begin() + static_cast<std::ptrdiff_t>(rng() % bytes.size()), static_cast<uint8_t>(rng()));
    }
    const std::string m = verify_message(bytes);
    EXPECT_NE(m, "") << "iteration " << it << " went unnoticed";
    EXPECT_NE(load_message(bytes), "") << "iteration " << it;
    caught += !m.empty();
  }
  EXPECT_GT(caught, kIterations * 9 / 10);
}

}  // namespace
}  // namespace isotope
