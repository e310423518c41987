// The box reader: any box of any source (raw, HDF5 contiguous or chunked and compressed, NRRD
// attached, detached, big-endian or gzip) equals the same nodes of read_volume, also when read
// from several threads at once, and every bad box or file is rejected with a message that says where.
#include "io/volume/box_reader.h"

#include <gtest/gtest.h>
#include <hdf5.h>
#include <zlib.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <bit>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iterator>
#include <limits>
#include <memory>
#include <optional>
#include <random>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include "io/volume/held_box_reader.h"
#include "io/volume/volume_reader.h"
#include "isotope/error.h"
#include "tests/support/byte_files.h"
#include "tests/support/io_error_of.h"
#include "tests/support/temp_dir_test.h"

namespace isotope {
namespace {

namespace fs = std::filesystem;

using testing::Bytes;
using testing::bytes_of;
using testing::gzip;
using testing::read_bytes;
using testing::write_file;
using Xyz = std::array<int64_t, 3>;
using testing::io_error_of;

const fs::path kData = ISOTOPE_TEST_DATA;
const std::string kNeghip = (kData / "neghip_66x66x66_uint8.raw").string();
const std::string kHydrogen = (kData / "hydrogen_64x64x64_float32.raw").string();

const char* const kSharedRaw[] = {"bolt_70x123x66_uint8.raw", "hydrogen_64x64x64_float32.raw",
                                  "ironProt_68x68x68_uint8.raw", "neghip_66x66x66_uint8.raw"};
const char* const kSharedH5[] = {"bolt.h5", "hydrogen.h5", "ironProt.h5", "neghip.h5"};

using BoxReaderTest = testing::TempDirTest;

// ---------------------------------------------------------------- files

// Every element of a float32 file with its bytes reversed.
Bytes swapped_floats(const Bytes& little) {
  Bytes out = little;
  for (size_t i = 0; i + 4 <= out.size(); i += 4)
    std::reverse(out.begin() + static_cast<std::ptrdiff_t>(i), out.begin() + static_cast<std::ptrdiff_t>(i + 4));
  return out;
}

// "NRRD0004", the fields of a 3-D volume, EXTRA fields, and the blank line that ends the header.
std::string nrrd_header(const std::string& sizes, const std::string& type, const std::string& encoding,
                        const std::vector<std::string>& extra = {}) {
  std::string text = "NRRD0004\ndimension: 3\nsizes: " + sizes + "\ntype: " + type + "\nencoding: " + encoding + "\n";
  for (const auto& f : extra) text += f + "\n";
  return text + "\n";
}

// One dataset of shape (z, y, x) = ZYX from DATA (none written if null); chunked and deflated when
// CHUNK is given; after a user block of USER_BLOCK bytes (0 or a power of 2 from 512); LAYOUT sets
// anything else of its creation properties.
void write_h5(const std::string& path, hid_t file_type, hid_t memory_type, const std::array<hsize_t, 3>& zyx,
              const void* data, const std::vector<hsize_t>& chunk = {}, hsize_t user_block = 0,
              const std::function<void(hid_t dcpl)>& layout = {}) {
  const hid_t fcpl = H5Pcreate(H5P_FILE_CREATE);
  EXPECT_GE(H5Pset_userblock(fcpl, user_block), 0);
  const hid_t file = H5Fcreate(path.c_str(), H5F_ACC_TRUNC, fcpl, H5P_DEFAULT);
  H5Pclose(fcpl);
  ASSERT_GE(file, 0) << path;
  const hid_t space = H5Screate_simple(3, zyx.data(), nullptr);
  const hid_t dcpl = H5Pcreate(H5P_DATASET_CREATE);
  if (!chunk.empty()) {
    EXPECT_GE(H5Pset_chunk(dcpl, 3, chunk.data()), 0);
    EXPECT_GE(H5Pset_deflate(dcpl, 6), 0);
  }
  if (layout) layout(dcpl);
  const hid_t ds = H5Dcreate2(file, "/volume", file_type, space, H5P_DEFAULT, dcpl, H5P_DEFAULT);
  EXPECT_GE(ds, 0) << path;
  if (data) {
    EXPECT_GE(H5Dwrite(ds, memory_type, H5S_ALL, H5S_ALL, H5P_DEFAULT, data), 0);
  }
  H5Dclose(ds);
  H5Pclose(dcpl);
  H5Sclose(space);
  H5Fclose(file);
}

// ---------------------------------------------------------------- boxes

struct Box {
  Xyz lo, size;
};

std::string box_text(const Box& b) {
  return "box lo (" + std::to_string(b.lo[0]) + "," + std::to_string(b.lo[1]) + "," + std::to_string(b.lo[2]) +
         ") size (" + std::to_string(b.size[0]) + "," + std::to_string(b.size[1]) + "," + std::to_string(b.size[2]) +
         ")";
}

int64_t box_nodes(const Box& b) { return b.size[0] * b.size[1] * b.size[2]; }

// The nodes of B cut out of a whole volume: what read_box must return.
std::vector<float> cut(const Volume& v, const Box& b) {
  std::vector<float> out;
  for (int64_t z = 0; z < b.size[2]; ++z)
    for (int64_t y = 0; y < b.size[1]; ++y)
      for (int64_t x = 0; x < b.size[0]; ++x) out.push_back(v.at(b.lo[0] + x, b.lo[1] + y, b.lo[2] + z));
  return out;
}

std::vector<float> read(const BoxReader& r, const Box& b) {
  std::vector<float> out(static_cast<size_t>(box_nodes(b)), -12345.0f);
  r.read_box(b.lo, b.size, out.data());
  return out;
}

Box random_box(const Xyz& dims, std::mt19937_64& rng) {
  Box b;
  for (int axis = 0; axis < 3; ++axis) {
    b.lo[axis] = std::uniform_int_distribution<int64_t>(0, dims[axis] - 1)(rng);
    b.size[axis] = std::uniform_int_distribution<int64_t>(1, dims[axis] - b.lo[axis])(rng);
  }
  return b;
}

// The shapes whose file layout differs (whole volume, planes, rows, single nodes, faces) and
// random boxes besides.
std::vector<Box> test_boxes(const Xyz& d, uint64_t seed) {
  std::mt19937_64 rng(seed);
  const Xyz corner = {std::min<int64_t>(d[0], 5), std::min<int64_t>(d[1], 6), std::min<int64_t>(d[2], 7)};
  std::vector<Box> boxes = {
      {{0, 0, 0}, d},                                                    // whole volume: one contiguous run
      {{0, 0, 0}, {1, 1, 1}},                                            // first node
      {{d[0] - 1, d[1] - 1, d[2] - 1}, {1, 1, 1}},                       // last node
      {{d[0] / 2, d[1] / 3, d[2] / 4}, {1, 1, 1}},                       // one inner node
      {{0, d[1] / 2, d[2] / 2}, {d[0], 1, 1}},                           // one whole row
      {{1, d[1] - 1, 0}, {d[0] - 2, 1, 1}},                              // part of a row
      {{0, 0, d[2] / 2}, {d[0], d[1], 1}},                               // one whole plane
      {{0, 0, 1}, {d[0], d[1], d[2] - 2}},                               // whole planes
      {{0, 1, 2}, {d[0], d[1] - 2, 3}},                                  // whole rows, part of planes
      {{d[0] / 2, 0, 0}, {1, d[1], d[2]}},                               // an x = const slice: a node per row
      {{0, 0, 0}, {d[0], d[1], 1}},                                      // face z = 0
      {{0, 0, d[2] - 1}, {d[0], d[1], 1}},                               // face z = max
      {{0, 0, 0}, {d[0], 1, d[2]}},                                      // face y = 0
      {{0, d[1] - 1, 0}, {d[0], 1, d[2]}},                               // face y = max
      {{0, 0, 0}, {1, d[1], d[2]}},                                      // face x = 0
      {{d[0] - 1, 0, 0}, {1, d[1], d[2]}},                               // face x = max
      {{d[0] - corner[0], d[1] - corner[1], d[2] - corner[2]}, corner},  // the far corner
  };
  for (int i = 0; i < 24; ++i) boxes.push_back(random_box(d, rng));
  return boxes;
}

// Every box read from R equals the same nodes of EXPECTED, value for value.
void expect_boxes_match(const BoxReader& r, const Volume& expected, uint64_t seed) {
  ASSERT_EQ(r.info().dims, expected.dims);
  for (const Box& b : test_boxes(expected.dims, seed)) {
    SCOPED_TRACE(box_text(b));
    const std::vector<float> got = read(r, b);
    const std::vector<float> want = cut(expected, b);
    const auto diff = std::mismatch(got.begin(), got.end(), want.begin());
    EXPECT_TRUE(diff.first == got.end()) << "first difference at box index " << diff.first - got.begin() << ": read "
                                         << *diff.first << ", expected " << *diff.second;
  }
}

void expect_info(const BoxReader& r, const Volume& v, const std::string& type, int bytes, bool integer) {
  EXPECT_EQ(r.info().dims, v.dims);
  EXPECT_EQ(r.info().spacing, v.spacing);
  EXPECT_EQ(r.info().origin, v.origin);
  EXPECT_EQ(r.info().type, type);
  EXPECT_EQ(r.info().element_bytes, bytes);
  EXPECT_EQ(r.info().is_integer, integer);
}

// THREADS threads each read every box (each from a different start) and must get what one
// thread reading them in order gets.
void expect_concurrent_reads_match(const BoxReader& r, int threads) {
  const std::vector<Box> boxes = test_boxes(r.info().dims, 99);
  std::vector<std::vector<float>> sequential;
  for (const Box& b : boxes) sequential.push_back(read(r, b));
  std::vector<std::vector<std::vector<float>>> results(static_cast<size_t>(threads));
  std::vector<std::thread> pool;
  for (int t = 0; t < threads; ++t) {
    pool.emplace_back([&, t] {
      auto& mine = results[static_cast<size_t>(t)];
      mine.resize(boxes.size());
      for (size_t k = 0; k < boxes.size(); ++k) {
        const size_t i = (k + static_cast<size_t>(t) * 7) % boxes.size();
        mine[i] = read(r, boxes[i]);
      }
    });
  }
  for (auto& th : pool) th.join();
  for (int t = 0; t < threads; ++t) {
    for (size_t i = 0; i < boxes.size(); ++i)
      EXPECT_TRUE(results[static_cast<size_t>(t)][i] == sequential[i]) << "thread " << t << ", " << box_text(boxes[i]);
  }
}

std::unique_ptr<BoxReader> open_reader(const std::string& spec, const std::string& scratch) {
  return open_box_reader({spec, {}, {}}, scratch);
}

// ---------------------------------------------------------------- shared volumes

TEST_F(BoxReaderTest, EveryBoxOfEverySharedRawVolumeEqualsReadVolume) {
  uint64_t seed = 1;
  for (const char* name : kSharedRaw) {
    SCOPED_TRACE(name);
    const std::string p = (kData / name).string();
    const Volume whole = read_volume({p, {}, {}});
    const auto r = open_reader(p, dir_.string());
    const bool is_float = std::string(name).find("float32") != std::string::npos;
    expect_info(*r, whole, is_float ? "float32" : "uint8", is_float ? 4 : 1, !is_float);
    expect_boxes_match(*r, whole, seed++);
  }
}

TEST_F(BoxReaderTest, EveryBoxOfEverySharedHdf5VolumeEqualsReadVolume) {
  uint64_t seed = 100;
  for (const char* name : kSharedH5) {
    SCOPED_TRACE(name);
    const std::string p = (kData / name).string();
    const Volume whole = read_volume({p + ":/volume", {}, {}});
    const bool is_float = std::string(name) == "hydrogen.h5";
    for (const std::string& spec : {p, p + ":/volume"}) {  // the only 3-D dataset, or named
      const auto r = open_reader(spec, dir_.string());
      expect_info(*r, whole, is_float ? "float32" : "uint8", is_float ? 4 : 1, !is_float);
      expect_boxes_match(*r, whole, seed++);
    }
  }
}

// What a convert groups its tiles' reads by: a box of raw data costs its own rows, and so does
// one of a contiguous HDF5 dataset (the shared files' layout), read as raw data; one of a chunked
// dataset (its chunks decoded again for each box) is left to the stage.
TEST_F(BoxReaderTest, ABoxOfRawDataOrAContiguousHdf5DatasetCostsItsOwnBytesAndAChunkedOneIsLeftToTheStage) {
  for (const char* name : kSharedRaw)
    EXPECT_TRUE(open_reader((kData / name).string(), dir_.string())->reads_box_alone()) << name;
  for (const char* name : kSharedH5)
    EXPECT_TRUE(open_reader((kData / name).string() + ":/volume", dir_.string())->reads_box_alone()) << name;
  const std::vector<float> f32(4 * 5 * 6, 1.5f);
  write_h5(path("chunked.h5"), H5T_IEEE_F32LE, H5T_NATIVE_FLOAT, {4, 5, 6}, f32.data(), {2, 2, 2});
  EXPECT_FALSE(open_reader(path("chunked.h5"), dir_.string())->reads_box_alone());
}

TEST_F(BoxReaderTest, RawLayoutOverridesApplyAsInReadVolume) {
  fs::copy_file(kNeghip, path("unnamed.bin"));
  const VolumeSpec source{path("unnamed.bin"), Xyz{66, 66, 66}, ScalarType::uint8};
  const auto r = open_box_reader(source, dir_.string());
  expect_boxes_match(*r, read_volume(source), 7);
}

TEST_F(BoxReaderTest, RunsLongerThanTheStagingBufferAreReadInPieces) {
  // 2.7 MB of float64: whole planes and the whole volume span several 1 MiB staging pieces.
  const Xyz dims = {80, 70, 60};
  std::vector<double> values(80 * 70 * 60);
  for (size_t i = 0; i < values.size(); ++i) values[i] = static_cast<double>(i) * 0.25 - 1000.0;
  const std::string p = path("big_80x70x60_float64.raw");
  write_file(p, "", bytes_of(values, std::endian::little));
  const auto r = open_reader(p, dir_.string());
  Volume expected;
  expected.dims = dims;
  expected.values.assign(values.begin(), values.end());
  expect_info(*r, expected, "float64", 8, false);
  expect_boxes_match(*r, expected, 8);
  expect_boxes_match(*r, read_volume({p, {}, {}}), 9);
}

TEST_F(BoxReaderTest, RowsOfANarrowBoxAreReadSeveralAtACallAcrossTheStagingBuffer) {
  // Rows of 4000 bytes: a box narrower than the volume reads about 262 rows (1 MiB) a call, so a
  // box 700 rows deep takes three calls a plane, the last one short.
  const Xyz dims = {1000, 700, 5};
  std::vector<float> values(1000 * 700 * 5);
  for (size_t i = 0; i < values.size(); ++i) values[i] = static_cast<float>(i) * 0.5f;
  const std::string p = path("wide_1000x700x5_float32.raw");
  write_file(p, "", bytes_of(values, std::endian::little));
  const auto r = open_reader(p, dir_.string());
  Volume expected;
  expected.dims = dims;
  expected.values = values;
  for (const Box& b : std::vector<Box>{{{1, 0, 0}, {998, 700, 3}},
                                       {{0, 3, 1}, {999, 697, 2}},
                                       {{500, 0, 2}, {7, 700, 1}},
                                       {{999, 261, 0}, {1, 264, 3}}}) {
    SCOPED_TRACE(box_text(b));
    EXPECT_TRUE(read(*r, b) == cut(expected, b));
  }
  expect_boxes_match(*r, expected, 10);
  // The file cut short within a plane's second call: the read fails, naming the file.
  fs::resize_file(p, (1000 * 700 * 4 + 1000 * 400) * 4);
  const std::string msg = io_error_of([&] { read(*r, {{1, 0, 4}, {998, 700, 1}}); });
  EXPECT_CONTAINS(msg, p);
  EXPECT_CONTAINS(msg, "short read");
}

// ---------------------------------------------------------------- NRRD

TEST_F(BoxReaderTest, AttachedRawNrrdWithByteSkipEqualsReadVolume) {
  Bytes data = {0xde, 0xad, 0xbe};  // skipped
  const Bytes neghip = read_bytes(kNeghip);
  data.insert(data.end(), neghip.begin(), neghip.end());
  const std::string p = path("neghip.nrrd");
  write_file(p, nrrd_header("66 66 66", "uchar", "raw", {"byte skip: 3", "spacings: 0.5 2 3"}), data);
  const Volume whole = read_volume({p, {}, {}});
  const auto r = open_reader(p, dir_.string());
  expect_info(*r, whole, "uint8", 1, true);
  EXPECT_EQ(r->info().spacing, (std::array<double, 3>{0.5, 2, 3}));
  expect_boxes_match(*r, whole, 11);
  expect_boxes_match(*r, read_volume({kNeghip, {}, {}}), 12);
}

TEST_F(BoxReaderTest, DetachedRawNrrdEqualsReadVolume) {
  fs::create_directories(dir_ / "data");
  fs::copy_file(kHydrogen, dir_ / "data" / "hydrogen.raw");
  const std::string p = path("hydrogen.nhdr");
  write_file(p, nrrd_header("64 64 64", "float", "raw",
                            {"endian: little", "data file: data/hydrogen.raw", "space origin: (1,2,3)"}));
  const Volume whole = read_volume({p, {}, {}});
  const auto r = open_reader(p, dir_.string());
  expect_info(*r, whole, "float32", 4, false);
  EXPECT_EQ(r->info().origin, (std::array<double, 3>{1, 2, 3}));
  expect_boxes_match(*r, whole, 13);
}

TEST_F(BoxReaderTest, BigEndianNrrdIsByteswapped) {
  const std::string f32 = path("hydrogen_be.nrrd");
  write_file(f32, nrrd_header("64 64 64", "float", "raw", {"endian: big"}), swapped_floats(read_bytes(kHydrogen)));
  expect_boxes_match(*open_reader(f32, dir_.string()), read_volume({kHydrogen, {}, {}}), 14);

  std::vector<uint16_t> u16(9 * 7 * 5);
  std::vector<int16_t> i16(u16.size());
  for (size_t i = 0; i < u16.size(); ++i) {
    u16[i] = static_cast<uint16_t>(i * 211 + 0x0102);
    i16[i] = static_cast<int16_t>(static_cast<int>(i) * -97 + 300);
  }
  const std::string pu = path("u16_be.nrrd");
  const std::string pi = path("i16_be.nrrd");
  write_file(pu, nrrd_header("9 7 5", "ushort", "raw", {"endian: big"}), bytes_of(u16, std::endian::big));
  write_file(pi, nrrd_header("9 7 5", "short", "raw", {"endian: big"}), bytes_of(i16, std::endian::big));
  const auto ru = open_reader(pu, dir_.string());
  const auto ri = open_reader(pi, dir_.string());
  Volume expected_u, expected_i;
  expected_u.dims = expected_i.dims = {9, 7, 5};
  expected_u.values.assign(u16.begin(), u16.end());
  expected_i.values.assign(i16.begin(), i16.end());
  expect_info(*ru, expected_u, "uint16", 2, true);
  expect_info(*ri, expected_i, "int16", 2, true);
  expect_boxes_match(*ru, expected_u, 15);
  expect_boxes_match(*ri, expected_i, 16);
  expect_boxes_match(*ru, read_volume({pu, {}, {}}), 17);
}

// R reads TYPE as stored: any box, byte for byte the box of NATIVE, the volume's values in this
// machine's byte order, x fastest.
void expect_read_as_stored(const BoxReader& r, const Bytes& native, ScalarType type, const std::string& what) {
  ASSERT_EQ(r.stored_type(), type) << what;
  const auto& d = r.info().dims;
  const auto elem = static_cast<size_t>(r.info().element_bytes);
  for (const auto& [lo, size] : {std::pair{Xyz{0, 0, 0}, d},
                                 {Xyz{0, 0, 2}, Xyz{d[0], d[1], 2}},
                                 {Xyz{1, 2, 1}, Xyz{d[0] - 3, d[1] - 2, d[2] - 1}}}) {
    Bytes got(static_cast<size_t>(size[0] * size[1] * size[2]) * elem);
    r.read_box_stored(lo, size, got.data());
    Bytes want;
    for (int64_t z = lo[2]; z < lo[2] + size[2]; ++z)
      for (int64_t y = lo[1]; y < lo[1] + size[1]; ++y) {
        const auto at = static_cast<size_t>((z * d[1] + y) * d[0] + lo[0]) * elem;
        want.insert(want.end(), native.begin() + static_cast<std::ptrdiff_t>(at),
                    native.begin() + static_cast<std::ptrdiff_t>(at + static_cast<size_t>(size[0]) * elem));
      }
    EXPECT_EQ(got, want) << what << " box at " << lo[0] << "," << lo[1] << "," << lo[2];
  }
}

// Integers of one or two bytes are read as the file stores them, any box, byte for byte, in this
// machine's byte order (those of the other order swapped); floats are not.
TEST_F(BoxReaderTest, NativeIntegersOfRawFilesAreReadAsStored) {
  std::vector<uint16_t> u16(9 * 7 * 5);
  std::vector<int16_t> i16(u16.size());
  for (size_t i = 0; i < u16.size(); ++i) {
    u16[i] = static_cast<uint16_t>(i * 211 + 0x8102);
    i16[i] = static_cast<int16_t>(static_cast<int>(i) * -97 + 300);
  }
  const std::string pu = path("u_9x7x5_uint16.raw"), pi = path("i_9x7x5_int16.raw");
  write_file(pu, "", bytes_of(u16, std::endian::native));
  write_file(pi, "", bytes_of(i16, std::endian::native));
  expect_read_as_stored(*open_reader(pu, dir_.string()), read_bytes(pu), ScalarType::uint16, "uint16");
  expect_read_as_stored(*open_reader(pi, dir_.string()), read_bytes(pi), ScalarType::int16, "int16");
  expect_read_as_stored(*open_reader(kNeghip, dir_.string()), read_bytes(kNeghip), ScalarType::uint8, "neghip");
  EXPECT_EQ(open_reader(kHydrogen, dir_.string())->stored_type(), std::nullopt) << "float32";
  const std::string other = path("u16_other.nrrd");
  const std::endian foreign = std::endian::native == std::endian::little ? std::endian::big : std::endian::little;
  write_file(other,
             nrrd_header("9 7 5", "ushort", "raw", {foreign == std::endian::big ? "endian: big" : "endian: little"}),
             bytes_of(u16, foreign));
  expect_read_as_stored(*open_reader(other, dir_.string()), bytes_of(u16, std::endian::native), ScalarType::uint16,
                        "the other byte order");
}

// HDF5 datasets of integers of one or two bytes are read as they are, in this machine's byte order
// whatever the file's, chunked and deflated or not; other types are not.
TEST_F(BoxReaderTest, SmallIntegersOfHdf5DatasetsAreReadAsStoredInThisMachinesOrder) {
  const std::array<hsize_t, 3> zyx = {5, 7, 9};
  const size_t n = 5 * 7 * 9;
  std::vector<uint8_t> u8(n);
  std::vector<uint16_t> u16(n);
  std::vector<int16_t> i16(n);
  std::vector<int8_t> i8(n);
  std::vector<int32_t> i32(n);
  for (size_t i = 0; i < n; ++i) {
    u8[i] = static_cast<uint8_t>(i * 37 + 5);
    u16[i] = static_cast<uint16_t>(i * 211 + 0x8102);
    i16[i] = static_cast<int16_t>(static_cast<int>(i) * -97 + 300);
    i8[i] = static_cast<int8_t>(static_cast<int>(i % 200) - 100);
    i32[i] = static_cast<int32_t>(i) * -3;
  }
  const std::string p8 = path("u8.h5"), p16 = path("u16be.h5"), pi16 = path("i16.h5");
  write_h5(p8, H5T_STD_U8LE, H5T_NATIVE_UINT8, zyx, u8.data());
  write_h5(p16, H5T_STD_U16BE, H5T_NATIVE_UINT16, zyx, u16.data(), {2, 3, 4});
  write_h5(pi16, H5T_STD_I16LE, H5T_NATIVE_INT16, zyx, i16.data());
  expect_read_as_stored(*open_reader(p8 + ":/volume", dir_.string()), bytes_of(u8, std::endian::native),
                        ScalarType::uint8, "uint8");
  expect_read_as_stored(*open_reader(p16 + ":/volume", dir_.string()), bytes_of(u16, std::endian::native),
                        ScalarType::uint16, "uint16, big-endian and chunked");
  expect_read_as_stored(*open_reader(pi16 + ":/volume", dir_.string()), bytes_of(i16, std::endian::native),
                        ScalarType::int16, "int16");
  const std::string pi8 = path("i8.h5"), pi32 = path("i32.h5");
  write_h5(pi8, H5T_STD_I8LE, H5T_NATIVE_INT8, zyx, i8.data());
  write_h5(pi32, H5T_STD_I32LE, H5T_NATIVE_INT32, zyx, i32.data());
  EXPECT_EQ(open_reader(pi8 + ":/volume", dir_.string())->stored_type(), std::nullopt) << "int8";
  EXPECT_EQ(open_reader(pi32 + ":/volume", dir_.string())->stored_type(), std::nullopt) << "int32";
  EXPECT_EQ(open_reader((kData / "hydrogen.h5").string() + ":/volume", dir_.string())->stored_type(), std::nullopt)
      << "float32";
}

// The values of V as T, in this machine's byte order.
template <class T>
Bytes native_bytes(const Volume& v) {
  std::vector<T> out;
  for (const float f : v.values) out.push_back(static_cast<T>(f));
  return bytes_of(out, std::endian::native);
}

// A contiguous dataset of a type raw data has is read at its offset in the file, past a user
// block, in either byte order: the values HDF5 reads, the type as stored. Other types, and space
// the file never got, are read by HDF5.
TEST_F(BoxReaderTest, ContiguousHdf5DatasetsOfRawTypesAreReadAtTheirOffsetAsHdf5ReadsThem) {
  const std::array<hsize_t, 3> zyx = {5, 7, 9};
  const size_t n = 5 * 7 * 9;
  std::vector<double> values(n);
  for (size_t i = 0; i < n; ++i)
    values[i] = static_cast<double>((i * 37 + 11) % 251) - 20.25 * static_cast<double>(i % 3);
  struct Case {
    const char* name;
    hid_t file_type;
    bool read_as_raw;
    std::optional<ScalarType> stored;
  };
  const Case cases[] = {
      {"u8", H5T_STD_U8LE, true, ScalarType::uint8},      {"u8be", H5T_STD_U8BE, true, ScalarType::uint8},
      {"u16le", H5T_STD_U16LE, true, ScalarType::uint16}, {"u16be", H5T_STD_U16BE, true, ScalarType::uint16},
      {"i16le", H5T_STD_I16LE, true, ScalarType::int16},  {"i16be", H5T_STD_I16BE, true, ScalarType::int16},
      {"f32le", H5T_IEEE_F32LE, true, std::nullopt},      {"f32be", H5T_IEEE_F32BE, true, std::nullopt},
      {"f64le", H5T_IEEE_F64LE, true, std::nullopt},      {"f64be", H5T_IEEE_F64BE, true, std::nullopt},
      {"i8", H5T_STD_I8LE, false, std::nullopt},          {"i32be", H5T_STD_I32BE, false, std::nullopt},
  };
  uint64_t seed = 7;
  for (const Case& c : cases) {
    for (const hsize_t user_block : {hsize_t{0}, hsize_t{512}}) {
      SCOPED_TRACE(std::string(c.name) + ", user block " + std::to_string(user_block));
      // The values converted to the file's type by HDF5, from doubles in range for every type.
      std::vector<double> in = values;
      if (c.file_type == H5T_STD_U8LE || c.file_type == H5T_STD_U8BE || c.file_type == H5T_STD_U16LE ||
          c.file_type == H5T_STD_U16BE)
        for (double& v : in) v = std::abs(v);
      const std::string p = path(std::string(c.name) + std::to_string(user_block) + ".h5");
      write_h5(p, c.file_type, H5T_NATIVE_DOUBLE, zyx, in.data(), {}, user_block);
      const auto r = open_reader(p, dir_.string());
      EXPECT_EQ(r->reads_box_alone(), c.read_as_raw);
      EXPECT_EQ(r->stored_type(), c.stored);
      const Volume hdf5 = read_volume({p, {}, {}});
      expect_boxes_match(*r, hdf5, seed++);
      if (c.stored == ScalarType::uint8) expect_read_as_stored(*r, native_bytes<uint8_t>(hdf5), *c.stored, c.name);
      if (c.stored == ScalarType::uint16) expect_read_as_stored(*r, native_bytes<uint16_t>(hdf5), *c.stored, c.name);
      if (c.stored == ScalarType::int16) expect_read_as_stored(*r, native_bytes<int16_t>(hdf5), *c.stored, c.name);
    }
  }
  // Layouts HDF5 reads: space never allocated (the fill value), a compact dataset (in the object
  // header), values in an external file.
  const std::vector<float> ones(n, 1.25f);
  for (const std::string layout : {"unwritten", "compact", "external"}) {
    SCOPED_TRACE(layout);
    const std::string p = path(layout + ".h5"), outside = path(layout + ".values");
    const bool unwritten = layout == "unwritten";
    write_h5(p, H5T_IEEE_F32LE, H5T_NATIVE_FLOAT, zyx, unwritten ? nullptr : ones.data(), {}, 0, [&](hid_t dcpl) {
      if (unwritten) {
        EXPECT_GE(H5Pset_alloc_time(dcpl, H5D_ALLOC_TIME_LATE), 0);
        const float fill = 2.5f;
        EXPECT_GE(H5Pset_fill_value(dcpl, H5T_NATIVE_FLOAT, &fill), 0);
      } else if (layout == "compact") {
        EXPECT_GE(H5Pset_layout(dcpl, H5D_COMPACT), 0);
      } else {
        EXPECT_GE(H5Pset_external(dcpl, outside.c_str(), 0, H5F_UNLIMITED), 0);
      }
    });
    const auto r = open_reader(p, dir_.string());
    EXPECT_FALSE(r->reads_box_alone());
    EXPECT_EQ(read(*r, {{0, 0, 0}, {9, 7, 5}}), std::vector<float>(n, unwritten ? 2.5f : 1.25f));
  }
}

TEST_F(BoxReaderTest, GzipNrrdIsInflatedIntoScratchAndRemovedWithTheReader) {
  fs::create_directories(dir_ / "scratch");
  const std::string scratch = path("scratch");
  Bytes data = {1, 2, 3, 4, 5};  // a byte skip of gzip data counts decompressed bytes
  const Bytes hydrogen = read_bytes(kHydrogen);
  data.insert(data.end(), hydrogen.begin(), hydrogen.end());
  const std::string p = path("hydrogen.nrrd");
  write_file(p, nrrd_header("64 64 64", "float", "gzip", {"endian: little", "byte skip: 5"}), gzip(data));
  {
    const auto r = open_reader(p, scratch);
    ASSERT_EQ(std::distance(fs::directory_iterator(scratch), fs::directory_iterator()), 1);
    EXPECT_EQ(fs::file_size(fs::directory_iterator(scratch)->path()), hydrogen.size());
    expect_info(*r, read_volume({p, {}, {}}), "float32", 4, false);
    expect_boxes_match(*r, read_volume({p, {}, {}}), 18);
    expect_concurrent_reads_match(*r, 3);
  }
  EXPECT_TRUE(fs::is_empty(scratch)) << "the inflated copy outlived its reader";
}

TEST_F(BoxReaderTest, BigEndianGzipNrrdEqualsReadVolume) {
  const std::string p = path("hydrogen_be.nrrd");
  write_file(p, nrrd_header("64 64 64", "float", "gz", {"endian: big"}), gzip(swapped_floats(read_bytes(kHydrogen))));
  fs::create_directories(dir_ / "scratch");
  expect_boxes_match(*open_reader(p, path("scratch")), read_volume({kHydrogen, {}, {}}), 19);
  EXPECT_TRUE(fs::is_empty(path("scratch")));
}

TEST_F(BoxReaderTest, CorruptGzipNrrdFailsAtOpenAndLeavesNoScratchFile) {
  fs::create_directories(dir_ / "scratch");
  Bytes packed = gzip(read_bytes(kNeghip));
  packed.resize(packed.size() / 2);  // the stream ends early
  const std::string truncated = path("truncated.nrrd");
  write_file(truncated, nrrd_header("66 66 66", "uchar", "gzip"), packed);
  const std::string msg = io_error_of([&] { open_reader(truncated, path("scratch")); });
  EXPECT_CONTAINS(msg, truncated);
  EXPECT_CONTAINS(msg, "truncated");
  EXPECT_TRUE(fs::is_empty(path("scratch"))) << "a failed open left its scratch file";

  Bytes flipped = gzip(read_bytes(kNeghip));
  flipped[flipped.size() / 2] ^= 0xff;
  const std::string corrupt = path("corrupt.nrrd");
  write_file(corrupt, nrrd_header("66 66 66", "uchar", "gzip"), flipped);
  EXPECT_CONTAINS(io_error_of([&] { open_reader(corrupt, path("scratch")); }), corrupt);
  EXPECT_TRUE(fs::is_empty(path("scratch")));
}

TEST_F(BoxReaderTest, GzipNrrdWithoutAScratchDirectoryNamesTheDirectory) {
  const std::string p = path("small.nrrd");
  write_file(p, nrrd_header("2 2 2", "uchar", "gzip"), gzip({1, 2, 3, 4, 5, 6, 7, 8}));
  const std::string missing = path("no_such_dir");
  const std::string msg = io_error_of([&] { open_reader(p, missing); });
  EXPECT_CONTAINS(msg, missing);
  EXPECT_CONTAINS(msg, p);
}

TEST_F(BoxReaderTest, TruncatedRawNrrdIsRejectedAtOpen) {
  const std::string p = path("short.nrrd");
  write_file(p, nrrd_header("4 4 4", "uchar", "raw"), Bytes(63, 7));
  const std::string msg = io_error_of([&] { open_reader(p, dir_.string()); });
  EXPECT_CONTAINS(msg, p);
  EXPECT_CONTAINS(msg, "truncated");
}

// ---------------------------------------------------------------- HDF5 chunked and compressed

TEST_F(BoxReaderTest, ChunkedGzipHdf5EqualsReadVolume) {
  const std::array<hsize_t, 3> zyx = {19, 23, 37};
  const size_t n = 19 * 23 * 37;
  std::vector<float> f32(n);
  std::vector<uint16_t> u16(n);
  std::vector<int32_t> i32(n);
  for (size_t i = 0; i < n; ++i) {
    f32[i] = std::sin(static_cast<float>(i) * 0.01f) * 1000.0f;
    u16[i] = static_cast<uint16_t>((i * 7919) % 65536);
    i32[i] = static_cast<int32_t>(i) * -3 + 1000;
  }
  const std::string pf = path("f32.h5"), pu = path("u16.h5"), pi = path("i32.h5");
  write_h5(pf, H5T_IEEE_F32LE, H5T_NATIVE_FLOAT, zyx, f32.data(), {8, 8, 8});
  write_h5(pu, H5T_STD_U16LE, H5T_NATIVE_UINT16, zyx, u16.data(), {8, 8, 8});
  write_h5(pi, H5T_STD_I32BE, H5T_NATIVE_INT32, zyx, i32.data(), {5, 7, 9});
  const struct {
    std::string path, type;
    int bytes;
    bool integer;
  } cases[] = {{pf, "float32", 4, false}, {pu, "uint16", 2, true}, {pi, "int32", 4, true}};
  uint64_t seed = 200;
  for (const auto& c : cases) {
    SCOPED_TRACE(c.path);
    const Volume whole = read_volume({c.path, {}, {}});
    const auto r = open_reader(c.path + ":/volume", dir_.string());
    EXPECT_EQ(r->info().dims, (Xyz{37, 23, 19}));
    expect_info(*r, whole, c.type, c.bytes, c.integer);
    expect_boxes_match(*r, whole, seed++);
  }
  Volume expected;
  expected.dims = {37, 23, 19};
  expected.values.assign(u16.begin(), u16.end());
  expect_boxes_match(*open_reader(pu, dir_.string()), expected, 300);
}

// A filter that changes nothing and counts the chunks it decodes.
std::atomic<int> g_chunks_decoded{0};
size_t count_decoded(unsigned int flags, size_t, const unsigned int[], size_t nbytes, size_t*, void**) {
  if (flags & H5Z_FLAG_REVERSE) g_chunks_decoded.fetch_add(1);
  return nbytes;
}
constexpr H5Z_filter_t kCountingFilter = 300;  // in the range HDF5 leaves for testing

// Boxes of whole planes, each a quarter of a chunk's depth, as the one-shot march reads windows:
// with a chunk cache that holds it, a layer of chunks across the plane (6 of 256 KB, more than
// HDF5's default cache) is decoded once, not once for every box that cuts it.
TEST_F(BoxReaderTest, ChunksDeeperThanTheBoxesAreDecodedOnce) {
  const H5Z_class2_t filter{H5Z_CLASS_T_VERS, kCountingFilter, 1, 1, "count", nullptr, nullptr, count_decoded};
  ASSERT_GE(H5Zregister(&filter), 0);
  const hsize_t zyx[3] = {64, 128, 192}, chunk[3] = {32, 64, 64};
  std::vector<uint16_t> values(64 * 128 * 192);
  for (size_t i = 0; i < values.size(); ++i) values[i] = static_cast<uint16_t>(i * 7919);
  const std::string p = path("counted.h5");
  {
    const hid_t file = H5Fcreate(p.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT);
    const hid_t space = H5Screate_simple(3, zyx, nullptr);
    const hid_t dcpl = H5Pcreate(H5P_DATASET_CREATE);
    ASSERT_GE(H5Pset_chunk(dcpl, 3, chunk), 0);
    ASSERT_GE(H5Pset_filter(dcpl, kCountingFilter, H5Z_FLAG_MANDATORY, 0, nullptr), 0);
    const hid_t ds = H5Dcreate2(file, "/volume", H5T_STD_U16LE, space, H5P_DEFAULT, dcpl, H5P_DEFAULT);
    ASSERT_GE(H5Dwrite(ds, H5T_NATIVE_UINT16, H5S_ALL, H5S_ALL, H5P_DEFAULT, values.data()), 0);
    H5Dclose(ds), H5Pclose(dcpl), H5Sclose(space), H5Fclose(file);
  }
  const auto decoded = [&](uint64_t cache_bytes) {
    const auto reader = open_box_reader({p + ":/volume", {}, {}}, dir_.string(), cache_bytes);
    g_chunks_decoded = 0;
    std::vector<uint16_t> layers(8 * 128 * 192);
    for (int64_t z = 0; z < 64; z += 8) {
      reader->read_box_stored({0, 0, z}, {192, 128, 8}, reinterpret_cast<unsigned char*>(layers.data()));
      EXPECT_EQ(std::memcmp(layers.data(), values.data() + z * 128 * 192, layers.size() * 2), 0) << z;
    }
    return g_chunks_decoded.load();
  };
  EXPECT_EQ(decoded(uint64_t{256} << 20), 2 * 2 * 3);
  // HDF5's default, and a cache smaller than the layer (1.5 MB), which the reader does not set:
  // chunks decoded again.
  EXPECT_GT(decoded(0), 2 * 2 * 3);
  EXPECT_GT(decoded(uint64_t{1400} << 10), 2 * 2 * 3);
}

// ---------------------------------------------------------------- threads

TEST_F(BoxReaderTest, ConcurrentRawReadsEqualSequentialReads) {
  const auto r = open_reader(kHydrogen, dir_.string());
  expect_concurrent_reads_match(*r, 4);
  const auto u8 = open_reader((kData / "bolt_70x123x66_uint8.raw").string(), dir_.string());
  expect_concurrent_reads_match(*u8, 2);
}

TEST_F(BoxReaderTest, ConcurrentHdf5ReadsEqualSequentialReadsAlongsideReadVolume) {
  const std::array<hsize_t, 3> zyx = {19, 23, 37};
  std::vector<float> f32(19 * 23 * 37);
  for (size_t i = 0; i < f32.size(); ++i) f32[i] = static_cast<float>(i % 1013) * 0.5f;
  write_h5(path("chunked.h5"), H5T_IEEE_F32LE, H5T_NATIVE_FLOAT, zyx, f32.data(), {8, 8, 8});
  const auto chunked = open_reader(path("chunked.h5"), dir_.string());
  const auto shared = open_reader((kData / "ironProt.h5").string(), dir_.string());
  // Other HDF5 users of the process take the same lock, so a whole-volume read may run alongside.
  std::thread whole([&] {
    for (int i = 0; i < 3; ++i) EXPECT_EQ(read_volume({path("chunked.h5"), {}, {}}).values, f32);
  });
  expect_concurrent_reads_match(*chunked, 4);
  expect_concurrent_reads_match(*shared, 3);
  whole.join();
}

// ---------------------------------------------------------------- the input held whole

// Another reader, counting the values it is asked for, in either form.
class CountingReader final : public BoxReader {
 public:
  explicit CountingReader(const BoxReader& input) : input_(input) { info_ = input.info(); }
  void read_box(const Xyz& lo, const Xyz& size, float* out) const override {
    nodes += size[0] * size[1] * size[2];
    input_.read_box(lo, size, out);
  }
  bool reads_box_alone() const override { return input_.reads_box_alone(); }
  std::optional<ScalarType> stored_type() const override { return input_.stored_type(); }
  void read_box_stored(const Xyz& lo, const Xyz& size, unsigned char* out) const override {
    nodes += size[0] * size[1] * size[2];
    input_.read_box_stored(lo, size, out);
  }
  mutable std::atomic<int64_t> nodes{0};

 private:
  const BoxReader& input_;
};

// Every box of a held reader equals the same nodes of the volume, whichever threads ask first and
// however many planes a read takes (a plane, or the whole file), each value read from its input once.
TEST_F(BoxReaderTest, AHeldReaderGivesEveryBoxOfItsInputReadingEachValueOnce) {
  // uint16 beyond a byte's range, so that a value decoded as the wrong type shows.
  std::vector<uint16_t> u16(23 * 17 * 29);
  for (size_t i = 0; i < u16.size(); ++i) u16[i] = static_cast<uint16_t>(i * 2654435761u >> 16);
  const std::string wide = path("wide_23x17x29_uint16.raw");
  write_file(wide, "", bytes_of(u16, std::endian::little));
  std::vector<std::string> files = {wide};
  for (const char* name : kSharedRaw) files.push_back((kData / name).string());
  for (const std::string& file : files) {
    const auto input = open_reader(file, dir_.string());
    const Volume whole = read_volume({file, {}, {}});
    // Integers of one or two bytes are held as the file stores them, the rest as float.
    const uint64_t nodes = static_cast<uint64_t>(whole.node_count());
    EXPECT_EQ(HeldBoxReader::held_bytes(*input),
              nodes * (input->info().is_integer ? static_cast<uint64_t>(input->info().element_bytes) : 4));
    const std::vector<Box> boxes = test_boxes(whole.dims, 5);
    for (const int64_t read_bytes : {int64_t{1}, HeldBoxReader::kReadBytes}) {
      SCOPED_TRACE(file + ", " + std::to_string(read_bytes) + " bytes a read");
      const CountingReader counted(*input);
      const HeldBoxReader held(counted, read_bytes);
      EXPECT_TRUE(held.in_memory());
      // Three threads from the start, each through the boxes in its own order, so that they meet
      // planes not yet read.
      std::vector<std::thread> pool;
      std::atomic<int> wrong{0};
      for (size_t t = 0; t < 3; ++t)
        pool.emplace_back([&, t] {
          for (size_t k = 0; k < boxes.size(); ++k) {
            const Box& b = boxes[(k * (2 * t + 1) + t) % boxes.size()];
            if (read(held, b) != cut(whole, b)) ++wrong;
          }
        });
      for (std::thread& th : pool) th.join();
      EXPECT_EQ(wrong.load(), 0);
      expect_boxes_match(held, whole, 7);
      EXPECT_EQ(counted.nodes.load(), whole.node_count());
    }
  }
}

TEST_F(BoxReaderTest, AHeldReaderFailsEveryBoxThatReachesAValueItsInputRefuses) {
  std::vector<float> values(9 * 8 * 7, 1.5f);
  values[(5 * 8 + 4) * 9 + 3] = std::numeric_limits<float>::quiet_NaN();  // (3, 4, 5)
  const std::string raw = path("nan_9x8x7_float32.raw");
  write_file(raw, "", bytes_of(values, std::endian::little));
  const auto input = open_reader(raw, dir_.string());
  const CountingReader counted(*input);
  const HeldBoxReader held(counted, 1);  // a plane a read
  EXPECT_EQ(read(held, {{0, 0, 0}, {9, 8, 3}}), std::vector<float>(9 * 8 * 3, 1.5f));
  // The read of plane 5 fails, and every box that reaches it after, with the input's message;
  // the planes before it stay held, and the failed read is not tried again.
  for (int i = 0; i < 2; ++i) {
    const std::string nan = io_error_of([&] { read(held, {{0, 0, 4}, {2, 2, 2}}); });
    EXPECT_CONTAINS(nan, raw);
    EXPECT_CONTAINS(nan, "(x,y,z) = (3,4,5)");
  }
  EXPECT_EQ(read(held, {{1, 1, 1}, {8, 7, 4}}), std::vector<float>(8 * 7 * 4, 1.5f));
  EXPECT_EQ(counted.nodes.load(), 9 * 8 * 6);  // planes 0 .. 5, each once
  EXPECT_THROW(read(held, {{0, 0, 0}, {10, 1, 1}}), InvalidInput);
}

// ---------------------------------------------------------------- rejected values and boxes

TEST_F(BoxReaderTest, NanInABoxIsNamedByItsGlobalCoordinates) {
  std::vector<float> values(9 * 8 * 7, 1.5f);
  values[(5 * 8 + 4) * 9 + 3] = std::numeric_limits<float>::quiet_NaN();  // (3, 4, 5)
  values[(6 * 8 + 7) * 9 + 8] = std::numeric_limits<float>::infinity();   // (8, 7, 6)
  const std::string raw = path("nan_9x8x7_float32.raw");
  write_file(raw, "", bytes_of(values, std::endian::little));
  const std::string h5 = path("nan.h5"), contiguous = path("nan_contiguous.h5");
  write_h5(h5, H5T_IEEE_F32LE, H5T_NATIVE_FLOAT, {7, 8, 9}, values.data(), {4, 4, 4});
  write_h5(contiguous, H5T_IEEE_F32LE, H5T_NATIVE_FLOAT, {7, 8, 9}, values.data());
  for (const std::string& p : {raw, h5, contiguous}) {
    SCOPED_TRACE(p);
    const auto r = open_reader(p, dir_.string());
    const std::string nan = io_error_of([&] { read(*r, {{2, 3, 4}, {3, 3, 3}}); });
    EXPECT_CONTAINS(nan, p);
    EXPECT_CONTAINS(nan, "(x,y,z) = (3,4,5)");
    const std::string inf = io_error_of([&] { read(*r, {{4, 4, 6}, {5, 4, 1}}); });
    EXPECT_CONTAINS(inf, "(x,y,z) = (8,7,6)");
    EXPECT_EQ(read(*r, {{0, 0, 0}, {9, 8, 5}}), std::vector<float>(9 * 8 * 5, 1.5f));  // z < 5: all finite
    // Unchecked, the same values, NaN and infinity included, bit for bit.
    std::vector<float> whole(values.size());
    r->read_box_unchecked({0, 0, 0}, {9, 8, 7}, whole.data());
    EXPECT_EQ(std::memcmp(whole.data(), values.data(), values.size() * sizeof(float)), 0);
  }
}

TEST_F(BoxReaderTest, TruncatedRawIsRejectedAtOpen) {
  const std::string p = path("short_4x4x4_uint16.raw");
  write_file(p, "", Bytes(4 * 4 * 4 * 2 - 1, 0));
  const std::string msg = io_error_of([&] { open_reader(p, dir_.string()); });
  EXPECT_CONTAINS(msg, p);
  EXPECT_CONTAINS(msg, "size 127 bytes, expected 128");
}

TEST_F(BoxReaderTest, RawFileTruncatedAfterOpenGivesAShortReadError) {
  const std::string p = path("shrinks_4x4x4_uint8.raw");
  write_file(p, "", Bytes(64, 9));
  const auto r = open_reader(p, dir_.string());
  EXPECT_EQ(read(*r, {{0, 0, 3}, {4, 4, 1}}), std::vector<float>(16, 9.0f));
  fs::resize_file(p, 40);
  const std::string msg = io_error_of([&] { read(*r, {{0, 0, 3}, {4, 4, 1}}); });
  EXPECT_CONTAINS(msg, p);
  EXPECT_CONTAINS(msg, "short read");
  EXPECT_EQ(read(*r, {{0, 0, 0}, {4, 4, 2}}), std::vector<float>(32, 9.0f));  // what is left still reads
}

// Read at its offset, a contiguous HDF5 dataset cut short after its file was opened is a short
// read (HDF5 read zeros past the end).
TEST_F(BoxReaderTest, ContiguousHdf5FileTruncatedAfterOpenGivesAShortReadError) {
  const std::vector<uint8_t> nines(64, 9);
  const std::string p = path("shrinks.h5");
  write_h5(p, H5T_STD_U8LE, H5T_NATIVE_UINT8, {4, 4, 4}, nines.data());
  const auto r = open_reader(p, dir_.string());
  ASSERT_TRUE(r->reads_box_alone());
  EXPECT_EQ(read(*r, {{0, 0, 3}, {4, 4, 1}}), std::vector<float>(16, 9.0f));
  fs::resize_file(p, fs::file_size(p) - 40);  // the dataset's last bytes, if nothing follows them
  const std::string msg = io_error_of([&] { read(*r, {{0, 0, 3}, {4, 4, 1}}); });
  EXPECT_CONTAINS(msg, p);
  EXPECT_CONTAINS(msg, "short read");
}

TEST_F(BoxReaderTest, BoxOutsideTheVolumeIsAnInvalidArgument) {
  const auto raw = open_reader(kNeghip, dir_.string());
  const auto h5 = open_reader((kData / "neghip.h5").string(), dir_.string());
  const Box outside[] = {
      {{-1, 0, 0}, {2, 2, 2}},
      {{0, -1, 0}, {2, 2, 2}},
      {{0, 0, -1}, {2, 2, 2}},  // before the start
      {{65, 0, 0}, {2, 1, 1}},
      {{0, 60, 0}, {1, 7, 1}},
      {{0, 0, 0}, {1, 1, 67}},  // past the end
      {{66, 0, 0}, {1, 1, 1}},
      {{0, 0, 0}, {1, -1, 1}},  // no such node, negative size
      {{0, 0, std::numeric_limits<int64_t>::max()}, {1, 1, std::numeric_limits<int64_t>::max()}},  // overflow
  };
  std::vector<float> sink(64);
  for (const BoxReader* r : {raw.get(), h5.get()}) {
    for (const Box& b : outside) {
      SCOPED_TRACE(box_text(b));
      EXPECT_THROW(r->read_box(b.lo, b.size, sink.data()), InvalidInput);
    }
  }
}

TEST_F(BoxReaderTest, Hdf5WithoutTheDatasetOrWithRankTwoIsRejectedAtOpen) {
  const std::string p = (kData / "neghip.h5").string();
  const std::string missing = io_error_of([&] { open_reader(p + ":/nope", dir_.string()); });
  EXPECT_CONTAINS(missing, p);
  EXPECT_CONTAINS(missing, "no dataset '/nope'");

  const std::string flat = path("flat.h5");
  const hid_t file = H5Fcreate(flat.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT);
  const hsize_t shape[2] = {4, 6};
  const hid_t space = H5Screate_simple(2, shape, nullptr);
  const hid_t ds = H5Dcreate2(file, "/flat", H5T_IEEE_F32LE, space, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
  H5Dclose(ds);
  H5Sclose(space);
  H5Fclose(file);
  EXPECT_CONTAINS(io_error_of([&] { open_reader(flat + ":/flat", dir_.string()); }), "rank 2, expected 3");
  EXPECT_CONTAINS(io_error_of([&] { open_reader(flat, dir_.string()); }), "contains no 3-D numeric dataset");
}

TEST_F(BoxReaderTest, MissingFileIsRejectedByName) {
  const std::string p = path("absent_4x4x4_uint8.raw");
  EXPECT_CONTAINS(io_error_of([&] { open_reader(p, dir_.string()); }), p + ": no such file");
  EXPECT_CONTAINS(io_error_of([&] { open_reader(path("absent.nrrd"), dir_.string()); }), "no such file");
  EXPECT_CONTAINS(io_error_of([&] { open_reader(path("absent.h5"), dir_.string()); }), "no such file");
}

}  // namespace
}  // namespace isotope
