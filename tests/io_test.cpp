// The I/O boundary: readers agree with each other on the shared volumes, every bad input
// becomes an IoError naming the file, and writers are atomic and round-trip exactly.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <hdf5.h>
#include <linux/fs.h>
#include <sys/ioctl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <sys/sysmacros.h>
#include <tbb/global_control.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <bit>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iterator>
#include <limits>
#include <map>
#include <sstream>
#include <stdexcept>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "engine/extract/extract_drivers.h"
#include "engine/mesh/vertex_normals.h"
#include "engine/synthetic/fields.h"
#include "io/file/atomic_file.h"
#include "io/file/direct_appends.h"
#include "io/file/region_writes.h"
#include "io/file/temporary_registry.h"
#include "io/mesh/mesh_writer.h"
#include "io/store/store_reader.h"
#include "io/volume/hdf5_reader.h"
#include "io/volume/raw_reader.h"
#include "io/volume/volume_reader.h"
#include "io/volume/volume_writer.h"
#include "isotope/detail/huge_page_allocator.h"
#include "isotope/error.h"
#include "tests/child_process.h"
#include "tests/io_error_of.h"
#include "tests/temp_dir_test.h"
#include "tests/test_support.h"

namespace isotope {
namespace {

namespace fs = std::filesystem;

const fs::path kData = ISOTOPE_TEST_DATA;

using IoTest = testing::TempDirTest;

void write_bytes(const std::string& path, const void* data, size_t size) {
  std::ofstream out(path, std::ios::binary);
  out.write(static_cast<const char*>(data), static_cast<std::streamsize>(size));
  ASSERT_TRUE(out.good()) << path;
}

template <typename T>
void write_values(const std::string& path, const std::vector<T>& values) {
  write_bytes(path, values.data(), values.size() * sizeof(T));
}

std::vector<unsigned char> read_bytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

using testing::io_error_of;

Volume sample_volume() {
  Volume v;
  v.dims = {5, 4, 3};
  v.spacing = {0.5, 2.0, 3.25};
  v.origin = {-1.0, 0.0, 7.5};
  for (int64_t i = 0; i < v.node_count(); ++i) v.values.push_back(static_cast<float>(i) * 0.37f - 4.0f);
  return v;
}

size_t open_hdf5_objects() { return static_cast<size_t>(H5Fget_obj_count(H5F_OBJ_ALL, H5F_OBJ_ALL)); }

// Test-side HDF5 writer for inputs the production writer never produces.
class H5Builder {
 public:
  explicit H5Builder(const std::string& path) {
    H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);
    file_ = H5Fcreate(path.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT);
    EXPECT_GE(file_, 0) << path;
  }
  ~H5Builder() {
    for (hid_t ds : datasets_) H5Dclose(ds);
    H5Fclose(file_);
  }
  H5Builder(const H5Builder&) = delete;
  H5Builder& operator=(const H5Builder&) = delete;

  // SHAPE in C order; a non-empty CHUNK means chunked and compressed: by gzip, or by the filter
  // FILTER (an HDF5 filter id: a plugin's, loaded by the library from its plugin folder).
  hid_t add(const std::string& name, hid_t file_type, hid_t mem_type, const std::vector<hsize_t>& shape,
            const void* data, const std::vector<hsize_t>& chunk = {}, H5Z_filter_t filter = H5Z_FILTER_DEFLATE) {
    const hid_t space = H5Screate_simple(static_cast<int>(shape.size()), shape.data(), nullptr);
    const hid_t lcpl = H5Pcreate(H5P_LINK_CREATE);
    H5Pset_create_intermediate_group(lcpl, 1);
    const hid_t dcpl = H5Pcreate(H5P_DATASET_CREATE);
    if (!chunk.empty()) {
      EXPECT_GE(H5Pset_chunk(dcpl, static_cast<int>(chunk.size()), chunk.data()), 0);
      if (filter == H5Z_FILTER_DEFLATE)
        EXPECT_GE(H5Pset_deflate(dcpl, 6), 0);
      else
        EXPECT_GE(H5Pset_filter(dcpl, filter, H5Z_FLAG_MANDATORY, 0, nullptr), 0) << "filter " << filter;
    }
    const hid_t ds = H5Dcreate2(file_, name.c_str(), file_type, space, lcpl, dcpl, H5P_DEFAULT);
    EXPECT_GE(ds, 0) << name;
    EXPECT_GE(H5Dwrite(ds, mem_type, H5S_ALL, H5S_ALL, H5P_DEFAULT, data), 0) << name;
    H5Pclose(dcpl);
    H5Pclose(lcpl);
    H5Sclose(space);
    datasets_.push_back(ds);
    return ds;
  }
  void attribute(hid_t ds, const char* name, const std::vector<double>& v) {
    const hsize_t n = v.size();
    const hid_t space = H5Screate_simple(1, &n, nullptr);
    const hid_t attr = H5Acreate2(ds, name, H5T_IEEE_F64LE, space, H5P_DEFAULT, H5P_DEFAULT);
    EXPECT_GE(H5Awrite(attr, H5T_NATIVE_DOUBLE, v.data()), 0);
    H5Aclose(attr);
    H5Sclose(space);
  }

 private:
  hid_t file_ = H5I_INVALID_HID;
  std::vector<hid_t> datasets_;
};

std::vector<float> iota_floats(size_t n) {
  std::vector<float> v(n);
  for (size_t i = 0; i < n; ++i) v[i] = static_cast<float>(i);
  return v;
}

// ---------------------------------------------------------------- shared volumes

struct SharedVolume {
  const char* raw;
  const char* h5;
  std::array<int64_t, 3> dims;
  float min, max;
};

const SharedVolume kShared[] = {
    {"ironProt_68x68x68_uint8.raw", "ironProt.h5", {68, 68, 68}, 0, 255},
    {"neghip_66x66x66_uint8.raw", "neghip.h5", {66, 66, 66}, 0, 255},
    {"hydrogen_64x64x64_float32.raw", "hydrogen.h5", {64, 64, 64}, 0, 1},
    {"bolt_70x123x66_uint8.raw", "bolt.h5", {70, 123, 66}, 0, 255},
};

TEST(SharedVolumes, EveryRawEqualsItsHdf5ValueForValue) {
  for (const auto& s : kShared) {
    SCOPED_TRACE(s.raw);
    const std::string raw_path = (kData / s.raw).string();
    const auto layout = parse_raw_name(raw_path);
    ASSERT_TRUE(layout.has_value());
    const Volume raw = read_raw(raw_path, *layout);
    const Volume h5 = read_hdf5((kData / s.h5).string(), "/volume");
    EXPECT_EQ(raw.dims, s.dims);
    EXPECT_EQ(h5.dims, s.dims);
    EXPECT_EQ(h5.spacing, (std::array<double, 3>{1, 1, 1}));
    EXPECT_EQ(h5.origin, (std::array<double, 3>{0, 0, 0}));
    ASSERT_EQ(raw.values.size(), static_cast<size_t>(s.dims[0] * s.dims[1] * s.dims[2]));
    ASSERT_EQ(h5.values.size(), raw.values.size());
    EXPECT_TRUE(raw.values == h5.values);
    EXPECT_EQ(*std::min_element(raw.values.begin(), raw.values.end()), s.min);
    EXPECT_EQ(*std::max_element(raw.values.begin(), raw.values.end()), s.max);
  }
}

TEST(SharedVolumes, ReadVolumeOpensBothSpellingsOfEachVolume) {
  for (const auto& s : kShared) {
    SCOPED_TRACE(s.raw);
    const Volume by_name = read_volume({(kData / s.h5).string(), {}, {}});
    const Volume by_spec = read_volume({(kData / s.h5).string() + ":/volume", {}, {}});
    const Volume raw = read_volume({(kData / s.raw).string(), {}, {}});
    EXPECT_EQ(by_name.dims, s.dims);
    EXPECT_TRUE(by_name.values == raw.values);
    EXPECT_TRUE(by_spec.values == raw.values);
  }
}

// ---------------------------------------------------------------- raw names

TEST(ParseRawName, ReadsDimsAndTypeFromTheEndOfTheStem) {
  const auto a = parse_raw_name("lobster_301x324x56_uint8.raw");
  ASSERT_TRUE(a.has_value());
  EXPECT_EQ(a->dims, (std::array<int64_t, 3>{301, 324, 56}));
  EXPECT_EQ(a->type, ScalarType::uint8);

  const auto b = parse_raw_name("/data/run_2x2x2_int16/my_vol_part_64x32x16_float32.raw");
  ASSERT_TRUE(b.has_value());
  EXPECT_EQ(b->dims, (std::array<int64_t, 3>{64, 32, 16}));
  EXPECT_EQ(b->type, ScalarType::float32);

  const auto c = parse_raw_name("8x9x10_u16.raw");
  ASSERT_TRUE(c.has_value());
  EXPECT_EQ(c->dims, (std::array<int64_t, 3>{8, 9, 10}));
  EXPECT_EQ(c->type, ScalarType::uint16);

  const auto d = parse_raw_name("Skull_256X256X113_DOUBLE.dat");
  ASSERT_TRUE(d.has_value());
  EXPECT_EQ(d->dims, (std::array<int64_t, 3>{256, 256, 113}));
  EXPECT_EQ(d->type, ScalarType::float64);
}

TEST(ParseRawName, AcceptsTheShortTypeAliases) {
  EXPECT_EQ(parse_scalar_type("u8"), ScalarType::uint8);
  EXPECT_EQ(parse_scalar_type("u16"), ScalarType::uint16);
  EXPECT_EQ(parse_scalar_type("i16"), ScalarType::int16);
  EXPECT_EQ(parse_scalar_type("f32"), ScalarType::float32);
  EXPECT_EQ(parse_scalar_type("float"), ScalarType::float32);
  EXPECT_EQ(parse_scalar_type("f64"), ScalarType::float64);
  EXPECT_EQ(parse_scalar_type("double"), ScalarType::float64);
  EXPECT_EQ(parse_scalar_type("int32"), std::nullopt);
  EXPECT_EQ(parse_scalar_type(""), std::nullopt);
}

TEST(ParseRawName, ReturnsNulloptWhenTheNameDoesNotSay) {
  for (const char* name : {"lobster.raw", "lobster_uint8.raw", "lobster_301x324_uint8.raw",
                           "lobster_301x324x56x2_uint8.raw", "lobster_301x324x56_int32.raw", "lobster_301x324x56.raw",
                           "lobster_0x324x56_uint8.raw", "lobster_-1x324x56_uint8.raw", "lobster_+1x324x56_uint8.raw",
                           "lobster_1xx2_uint8.raw", "lobster_1x2x3x_uint8.raw", "lobster_ 1x2x3_uint8.raw",
                           "lobster_99999999999999999999x1x1_uint8.raw", "_uint8.raw", ""}) {
    EXPECT_FALSE(parse_raw_name(name).has_value()) << name;
  }
}

TEST(ScalarTypes, NamesAndSizesMatchTheLayout) {
  EXPECT_STREQ(scalar_type_name(ScalarType::int16), "int16");
  EXPECT_EQ(scalar_type_size(ScalarType::uint8), 1);
  EXPECT_EQ(scalar_type_size(ScalarType::uint16), 2);
  EXPECT_EQ(scalar_type_size(ScalarType::int16), 2);
  EXPECT_EQ(scalar_type_size(ScalarType::float32), 4);
  EXPECT_EQ(scalar_type_size(ScalarType::float64), 8);
}

// ---------------------------------------------------------------- raw reader

TEST_F(IoTest, RawSizeMismatchNamesFileSizesAndLayout) {
  const std::string p = path("neghip_66x66x66_uint8.raw");
  write_values(p, std::vector<uint8_t>(287495));
  const std::string msg = io_error_of([&] { read_raw(p, *parse_raw_name(p)); });
  EXPECT_CONTAINS(msg, "neghip_66x66x66_uint8.raw");
  EXPECT_CONTAINS(msg, "size 287495 bytes, expected 287496 for 66x66x66 uint8");
}

TEST_F(IoTest, RawTruncatedFileIsRejected) {
  const std::string p = path("v_4x4x4_float32.raw");
  write_values(p, std::vector<float>(40));
  const std::string msg = io_error_of([&] { read_raw(p, *parse_raw_name(p)); });
  EXPECT_CONTAINS(msg, p);
  EXPECT_CONTAINS(msg, "size 160 bytes, expected 256");
}

TEST_F(IoTest, RawMissingFileIsRejectedByName) {
  const std::string p = path("absent_2x2x2_uint8.raw");
  const std::string msg = io_error_of([&] { read_raw(p, *parse_raw_name(p)); });
  EXPECT_CONTAINS(msg, p);
  EXPECT_CONTAINS(msg, "no such file");
}

TEST_F(IoTest, RawDirectoryInsteadOfFileIsRejected) {
  const std::string p = path("dir_2x2x2_uint8.raw");
  fs::create_directory(p);
  EXPECT_CONTAINS(io_error_of([&] { read_raw(p, *parse_raw_name(p)); }), "is a directory");
}

// The input policy (io/file/input_file.h): a FIFO without a writer would block every reader's open
// forever (this test then hangs until ctest's timeout); each reader refuses it by name instead,
// through a link too, and an NRRD header whose detached data file is a FIFO as well.
TEST_F(IoTest, NonRegularInputsAreRefused) {
  const std::string fifo = path("pipe");
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0644), 0);
  for (const std::string name : {"v_2x2x2_uint8.raw", "v.nrrd", "v.h5", "v.isotope"})
    fs::create_symlink(fifo, path(name));
  const auto source = [](const std::string& spec) {
    VolumeSpec s;
    s.path = spec;
    return s;
  };
  const auto refused = [](const std::string& msg) {
    return msg.find("is a FIFO, not a regular file") != std::string::npos;
  };
  EXPECT_PRED1(refused, io_error_of([&] { read_volume(source(path("v_2x2x2_uint8.raw"))); }));
  EXPECT_PRED1(refused, io_error_of([&] { read_volume(source(path("v.nrrd"))); }));
  EXPECT_PRED1(refused, io_error_of([&] { read_volume(source(path("v.h5") + ":/data")); }));
  EXPECT_PRED1(refused, io_error_of([&] { StoreReader store(path("v.isotope")); }));
  EXPECT_FALSE(is_store_file(path("v.isotope")));
  {
    std::ofstream(path("d.nhdr"))
        << "NRRD0004\ntype: uint8\ndimension: 3\nsizes: 2 2 2\nencoding: raw\ndata file: pipe\n";
  }
  EXPECT_PRED1(refused, io_error_of([&] { read_volume(source(path("d.nhdr"))); }));
}

TEST_F(IoTest, RawNanIsRejectedWithItsCoordinates) {
  const std::string p = path("v_4x3x5_float32.raw");
  Volume v;
  v.dims = {4, 3, 5};
  std::vector<float> values = iota_floats(60);
  v.values = values;
  values[v.index(2, 1, 3)] = std::numeric_limits<float>::quiet_NaN();
  values[v.index(3, 2, 4)] = std::numeric_limits<float>::quiet_NaN();  // later: not reported
  write_values(p, values);
  const std::string msg = io_error_of([&] { read_raw(p, *parse_raw_name(p)); });
  EXPECT_CONTAINS(msg, p);
  EXPECT_CONTAINS(msg, "(2,1,3)");
  EXPECT_CONTAINS(msg, "not finite");
}

TEST_F(IoTest, RawInfinityAndFloat64BeyondFloatRangeAreRejected) {
  const std::string inf = path("inf_2x1x1_float64.raw");
  write_values(inf, std::vector<double>{1.0, -std::numeric_limits<double>::infinity()});
  EXPECT_CONTAINS(io_error_of([&] { read_raw(inf, *parse_raw_name(inf)); }), "(1,0,0)");
  const std::string big = path("big_1x1x2_float64.raw");
  write_values(big, std::vector<double>{1.0, 1e300});
  EXPECT_CONTAINS(io_error_of([&] { read_raw(big, *parse_raw_name(big)); }), "(0,0,1)");
}

TEST_F(IoTest, RawDecodesEveryScalarTypeLittleEndianXFastest) {
  const std::string u16 = path("a_3x1x1_uint16.raw");
  write_values(u16, std::vector<uint8_t>{0x01, 0x00, 0x00, 0x01, 0xff, 0xff});
  EXPECT_EQ(read_raw(u16, *parse_raw_name(u16)).values, (std::vector<float>{1, 256, 65535}));

  const std::string i16 = path("b_1x3x1_int16.raw");
  write_values(i16, std::vector<int16_t>{-32768, -1, 32767});
  EXPECT_EQ(read_raw(i16, *parse_raw_name(i16)).values, (std::vector<float>{-32768, -1, 32767}));

  const std::string f64 = path("c_1x1x2_float64.raw");
  write_values(f64, std::vector<double>{0.1, -2.5});
  EXPECT_EQ(read_raw(f64, *parse_raw_name(f64)).values, (std::vector<float>{0.1f, -2.5f}));

  const std::string u8 = path("d_2x2x1_uint8.raw");
  write_values(u8, std::vector<uint8_t>{0, 1, 2, 255});
  const Volume v = read_raw(u8, *parse_raw_name(u8));
  EXPECT_EQ(v.at(1, 0, 0), 1.0f);
  EXPECT_EQ(v.at(0, 1, 0), 2.0f);
  EXPECT_EQ(v.at(1, 1, 0), 255.0f);
}

TEST_F(IoTest, RawZeroAndOverflowingDimsAreRejected) {
  const std::string p = path("x.raw");
  write_values(p, std::vector<uint8_t>(8));
  EXPECT_CONTAINS(io_error_of([&] { read_raw(p, {{2, 0, 2}, ScalarType::uint8}); }), ">= 1");
  EXPECT_CONTAINS(io_error_of([&] { read_raw(p, {{-2, 2, 2}, ScalarType::uint8}); }), ">= 1");
  const int64_t big = int64_t{1} << 31;
  EXPECT_CONTAINS(io_error_of([&] { read_raw(p, {{big, big, big}, ScalarType::uint8}); }), "too large");
  EXPECT_CONTAINS(io_error_of([&] { read_raw(p, {{big, big, 2}, ScalarType::float64}); }), "too large");
}

// ---------------------------------------------------------------- HDF5 reader

TEST_F(IoTest, Hdf5MissingFileIsRejectedByName) {
  const std::string p = path("absent.h5");
  const std::string msg = io_error_of([&] { read_hdf5(p, "/volume"); });
  EXPECT_CONTAINS(msg, p);
  EXPECT_CONTAINS(msg, "no such file");
}

TEST_F(IoTest, NonHdf5FileNamedH5IsRejected) {
  const std::string p = path("fake.h5");
  write_values(p, std::vector<uint8_t>(1000, 7));
  const std::string msg = io_error_of([&] { read_hdf5(p, "/volume"); });
  EXPECT_CONTAINS(msg, p);
  EXPECT_CONTAINS(msg, "not an HDF5 file");
  EXPECT_CONTAINS(io_error_of([&] { read_volume({p, {}, {}}); }), "not an HDF5 file");
}

TEST_F(IoTest, Hdf5MissingDatasetListsThe3dDatasetsThatExist) {
  const std::string p = path("many.h5");
  {
    H5Builder b(p);
    const auto v = iota_floats(24);
    b.add("/volume", H5T_IEEE_F32LE, H5T_NATIVE_FLOAT, {2, 3, 4}, v.data());
    b.add("/grp/density", H5T_STD_U8LE, H5T_NATIVE_FLOAT, {2, 3, 4}, v.data());
    b.add("/flat", H5T_IEEE_F32LE, H5T_NATIVE_FLOAT, {4, 6}, v.data());
  }
  const std::string msg = io_error_of([&] { read_hdf5(p, "/nope/missing"); });
  EXPECT_CONTAINS(msg, p);
  EXPECT_CONTAINS(msg, "no dataset '/nope/missing'");
  EXPECT_CONTAINS(msg, "/grp/density, /volume");
  EXPECT_EQ(msg.find("/flat"), std::string::npos) << msg;
  EXPECT_EQ(list_3d_datasets(p), (std::vector<std::string>{"/grp/density", "/volume"}));
}

TEST_F(IoTest, Hdf5RankOtherThanThreeIsRejected) {
  const std::string p = path("flat.h5");
  {
    H5Builder b(p);
    const auto v = iota_floats(24);
    b.add("/flat", H5T_IEEE_F32LE, H5T_NATIVE_FLOAT, {4, 6}, v.data());
  }
  const std::string msg = io_error_of([&] { read_hdf5(p, "/flat"); });
  EXPECT_CONTAINS(msg, p + ":/flat");
  EXPECT_CONTAINS(msg, "rank 2, expected 3");
}

TEST_F(IoTest, Hdf5NonNumericTypeIsRejected) {
  const std::string p = path("text.h5");
  {
    H5Builder b(p);
    const hid_t str = H5Tcopy(H5T_C_S1);
    H5Tset_size(str, 4);
    const std::string text(8 * 4, 'a');
    b.add("/text", str, str, {2, 2, 2}, text.data());
    H5Tclose(str);
  }
  EXPECT_CONTAINS(io_error_of([&] { read_hdf5(p, "/text"); }), "not numeric");
  EXPECT_TRUE(list_3d_datasets(p).empty());
  EXPECT_CONTAINS(io_error_of([&] { read_volume({p, {}, {}}); }), "no 3-D numeric dataset");
}

TEST_F(IoTest, Hdf5NanIsRejectedWithItsCoordinates) {
  const std::string p = path("nan.h5");
  std::vector<float> v = iota_floats(4 * 3 * 2);
  v[(1 * 3 + 2) * 4 + 3] = std::numeric_limits<float>::quiet_NaN();  // (x,y,z) = (3,2,1)
  {
    H5Builder b(p);
    b.add("/volume", H5T_IEEE_F32LE, H5T_NATIVE_FLOAT, {2, 3, 4}, v.data());
  }
  const std::string msg = io_error_of([&] { read_hdf5(p, "/volume"); });
  EXPECT_CONTAINS(msg, p);
  EXPECT_CONTAINS(msg, "(3,2,1)");
}

TEST_F(IoTest, Hdf5ChunkedGzipUint16ReadsExactlyWithAttributes) {
  const std::string p = path("chunked.h5");
  const int64_t nx = 17, ny = 13, nz = 11;  // not multiples of the chunk, so edge chunks are partial
  std::vector<uint16_t> v(static_cast<size_t>(nx * ny * nz));
  for (size_t i = 0; i < v.size(); ++i) v[i] = static_cast<uint16_t>((i * 7919u) % 65536u);
  {
    H5Builder b(p);
    const hid_t ds = b.add("/scan/volume", H5T_STD_U16LE, H5T_NATIVE_UINT16, {hsize_t(nz), hsize_t(ny), hsize_t(nx)},
                           v.data(), {3, 4, 5});
    b.attribute(ds, "spacing", {0.5, 2.0, 3.0});
    b.attribute(ds, "origin", {-1.0, 0.0, 4.5});
  }
  const Volume vol = read_hdf5(p, "/scan/volume");
  EXPECT_EQ(vol.dims, (std::array<int64_t, 3>{nx, ny, nz}));
  EXPECT_EQ(vol.spacing, (std::array<double, 3>{0.5, 2.0, 3.0}));
  EXPECT_EQ(vol.origin, (std::array<double, 3>{-1.0, 0.0, 4.5}));
  ASSERT_EQ(vol.values.size(), v.size());
  for (size_t i = 0; i < v.size(); ++i) ASSERT_EQ(vol.values[i], static_cast<float>(v[i])) << i;
  EXPECT_EQ(vol.at(16, 0, 0), static_cast<float>(v[16]));
}

TEST_F(IoTest, Hdf5Float64IsRoundedToFloat) {
  const std::string p = path("f64.h5");
  const std::vector<double> v{0.1, 1.0 / 3.0, -2.0, 1e-7, 5, 6, 7, 8};
  {
    H5Builder b(p);
    b.add("/volume", H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, {2, 2, 2}, v.data());
  }
  const Volume vol = read_hdf5(p, "/volume");
  for (size_t i = 0; i < v.size(); ++i) EXPECT_EQ(vol.values[i], static_cast<float>(v[i])) << i;
}

TEST_F(IoTest, Hdf5BadSpacingAttributeIsRejected) {
  const std::string p = path("badspacing.h5");
  {
    H5Builder b(p);
    const auto v = iota_floats(8);
    const hid_t ds = b.add("/volume", H5T_IEEE_F32LE, H5T_NATIVE_FLOAT, {2, 2, 2}, v.data());
    b.attribute(ds, "spacing", {1.0, 2.0});
  }
  EXPECT_CONTAINS(io_error_of([&] { read_hdf5(p, "/volume"); }), "'spacing' must hold 3 numbers");
}

TEST_F(IoTest, Hdf5ErrorPathsLeaveNoHandleOpen) {
  const std::string p = path("handles.h5");
  {
    H5Builder b(p);
    const auto v = iota_floats(24);
    b.add("/flat", H5T_IEEE_F32LE, H5T_NATIVE_FLOAT, {4, 6}, v.data());
    b.add("/volume", H5T_IEEE_F32LE, H5T_NATIVE_FLOAT, {2, 3, 4}, v.data());
  }
  const size_t before = open_hdf5_objects();
  io_error_of([&] { read_hdf5(p, "/flat"); });
  io_error_of([&] { read_hdf5(p, "/missing"); });
  EXPECT_EQ(read_hdf5(p, "/volume").values.size(), 24u);
  EXPECT_EQ(open_hdf5_objects(), before);
}

// The isotope command links HDF5's static archive (io/CMakeLists.txt), and a filter plugin links
// the shared library, which then loads beside it: a dataset compressed by a plugin (Debian's
// hdf5-filter-plugin: lz4, bzip2) reads through the command as the same values gzip-compressed.
TEST_F(IoTest, Hdf5DatasetsOfFilterPluginsReadThroughTheCommandAsWithGzip) {
  const int64_t n = 24;
  std::vector<uint16_t> v(static_cast<size_t>(n * n * n));
  for (int64_t z = 0, i = 0; z < n; ++z)
    for (int64_t y = 0; y < n; ++y)
      for (int64_t x = 0; x < n; ++x, ++i)
        v[static_cast<size_t>(i)] =
            static_cast<uint16_t>((x - 11) * (x - 11) + (y - 12) * (y - 12) + 2 * (z - 10) * (z - 10));
  auto extract = [&](const std::string& name, H5Z_filter_t filter) {
    const std::string h5 = path(name + ".h5"), mesh = path(name + ".ply");
    {
      H5Builder b(h5);
      b.add("/volume", H5T_STD_U16LE, H5T_NATIVE_UINT16, {hsize_t(n), hsize_t(n), hsize_t(n)}, v.data(), {8, 8, 8},
            filter);
    }
    const std::string log = path(name + ".log");
    EXPECT_EQ(testing::run_isotope({"extract", h5 + ":/volume", "--iso", "100.5", "-q", "-o", mesh}, log).code, 0)
        << name << ": " << testing::slurp(log);
    return testing::slurp(mesh);
  };
  const std::string gzip = extract("gzip", H5Z_FILTER_DEFLATE);
  ASSERT_GT(gzip.size(), 1000u);
  for (const auto& [name, filter] : {std::pair<const char*, H5Z_filter_t>{"lz4", 32004}, {"bzip2", 307}}) {
    EXPECT_GT(H5Zfilter_avail(filter), 0) << name << " (" << filter << "): no such HDF5 filter plugin here";
    EXPECT_TRUE(extract(name, filter) == gzip) << name;
  }
}

// ---------------------------------------------------------------- read_volume

TEST_F(IoTest, ReadVolumeSplitsTheSpecAtTheLastColonSlash) {
  fs::create_directory(path("odd:dir"));
  const std::string p = path("odd:dir/two.h5");
  {
    H5Builder b(p);
    const auto v = iota_floats(24);
    b.add("/a/first", H5T_IEEE_F32LE, H5T_NATIVE_FLOAT, {2, 3, 4}, v.data());
    b.add("/b/second", H5T_IEEE_F32LE, H5T_NATIVE_FLOAT, {4, 3, 2}, v.data());
  }
  EXPECT_EQ(read_volume({p + ":/b/second", {}, {}}).dims, (std::array<int64_t, 3>{2, 3, 4}));
  EXPECT_EQ(read_volume({p + ":/a/first", {}, {}}).dims, (std::array<int64_t, 3>{4, 3, 2}));
  const std::string msg = io_error_of([&] { read_volume({p, {}, {}}); });
  EXPECT_CONTAINS(msg, "/a/first, /b/second");
  EXPECT_CONTAINS(msg, p + ":/DATASET");
}

TEST_F(IoTest, ReadVolumeRawUsesOverridesBeforeTheName) {
  const std::string named = path("v_2x2x4_uint8.raw");
  std::vector<uint8_t> values(16);
  for (uint8_t i = 0; i < 16; ++i) values[i] = i;
  write_values(named, values);
  EXPECT_EQ(read_volume({named, {}, {}}).dims, (std::array<int64_t, 3>{2, 2, 4}));
  const Volume flat = read_volume({named, std::array<int64_t, 3>{4, 2, 2}, {}});
  EXPECT_EQ(flat.dims, (std::array<int64_t, 3>{4, 2, 2}));
  EXPECT_EQ(flat.at(3, 1, 1), 15.0f);
  const Volume wide = read_volume({named, std::array<int64_t, 3>{2, 2, 2}, ScalarType::uint16});
  EXPECT_EQ(wide.at(0, 0, 0), 256.0f);
  // A layout the volume cannot have is refused with the file and the dimensions named.
  EXPECT_CONTAINS(io_error_of([&] {
                    read_volume({named, std::array<int64_t, 3>{16, 1, 1}, {}});
                  }),
                  "v_2x2x4_uint8.raw: volume dimensions 16x1x1 (x by y by z): every axis needs 2 .. 524289 nodes");
}

TEST_F(IoTest, ReadVolumeAsksForDimsAndTypeWhenTheNameSaysNothing) {
  const std::string p = path("blob.bin");
  write_values(p, std::vector<uint8_t>(8));
  const std::string msg = io_error_of([&] { read_volume({p, {}, {}}); });
  EXPECT_CONTAINS(msg, p);
  EXPECT_CONTAINS(msg, "pass --dims and --type");
  EXPECT_CONTAINS(io_error_of([&] { read_volume({p, std::array<int64_t, 3>{2, 2, 2}, {}}); }), "cannot tell the type");
  EXPECT_EQ(read_volume({p, std::array<int64_t, 3>{2, 2, 2}, ScalarType::uint8}).values.size(), 8u);
}

TEST_F(IoTest, ReadVolumeReportsAMissingFileBeforeAskingForALayout) {
  const std::string p = path("typo.bin");
  const std::string msg = io_error_of([&] { read_volume({p, {}, {}}); });
  EXPECT_CONTAINS(msg, p + ": no such file");
  EXPECT_CONTAINS(io_error_of([&] { read_volume({dir_.string(), {}, {}}); }), "is a directory");
  EXPECT_CONTAINS(io_error_of([&] { read_volume({path("gone.h5") + ":/volume", {}, {}}); }), "no such file");
}

// ---------------------------------------------------------------- writers

TEST_F(IoTest, WriteHdf5ThenReadHdf5RoundTripsExactly) {
  const Volume v = sample_volume();
  const std::string p = path("out.h5");
  write_hdf5(v, p);
  const Volume back = read_hdf5(p, "/volume");
  EXPECT_EQ(back.dims, v.dims);
  EXPECT_EQ(back.spacing, v.spacing);
  EXPECT_EQ(back.origin, v.origin);
  EXPECT_EQ(back.values, v.values);
  EXPECT_EQ(entries(), (std::vector<std::string>{"out.h5"}));

  // Shape on disk is (z, y, x) float32.
  const hid_t f = H5Fopen(p.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
  const hid_t ds = H5Dopen2(f, "/volume", H5P_DEFAULT);
  const hid_t space = H5Dget_space(ds);
  const hid_t type = H5Dget_type(ds);
  hsize_t shape[3] = {0, 0, 0};
  H5Sget_simple_extent_dims(space, shape, nullptr);
  EXPECT_EQ(shape[0], 3u);
  EXPECT_EQ(shape[1], 4u);
  EXPECT_EQ(shape[2], 5u);
  EXPECT_GT(H5Tequal(type, H5T_IEEE_F32LE), 0);
  H5Tclose(type);
  H5Sclose(space);
  H5Dclose(ds);
  H5Fclose(f);
}

TEST_F(IoTest, WriteHdf5ReplacesAnExistingFile) {
  const std::string p = path("out.h5");
  write_values(p, std::vector<uint8_t>(100, 1));
  write_hdf5(sample_volume(), p);
  EXPECT_EQ(read_hdf5(p, "/volume").values, sample_volume().values);
  EXPECT_EQ(entries(), (std::vector<std::string>{"out.h5"}));
}

TEST_F(IoTest, WriteRawFloat32ThenReadRawRoundTripsExactly) {
  const Volume v = sample_volume();
  const std::string p = path("out_5x4x3_float32.raw");
  EXPECT_FALSE(write_raw(v, p, ScalarType::float32).is_mapped());
  EXPECT_EQ(fs::file_size(p), 60u * 4u);
  const Volume back = read_raw(p, *parse_raw_name(p));
  EXPECT_EQ(back.dims, v.dims);
  EXPECT_EQ(back.values, v.values);
  EXPECT_EQ(entries(), (std::vector<std::string>{"out_5x4x3_float32.raw"}));
}

// sample_volume spans [-4, 18.57]: min must become code 0 and max the type's top code.
TEST_F(IoTest, WriteRawIntegerTypesStretchMinToZeroAndMaxToTheTopCode) {
  const Volume v = sample_volume();
  const std::string p8 = path("u8.raw"), p16 = path("u16.raw");
  const RawEncoding e8 = write_raw(v, p8, ScalarType::uint8);
  const RawEncoding e16 = write_raw(v, p16, ScalarType::uint16);
  ASSERT_EQ(fs::file_size(p8), 60u);
  ASSERT_EQ(fs::file_size(p16), 120u);
  const std::vector<unsigned char> b8 = read_bytes(p8), b16 = read_bytes(p16);
  EXPECT_EQ(b8.front(), 0);
  EXPECT_EQ(b8.back(), 255);
  EXPECT_EQ(b16[0] | b16[1] << 8, 0);
  EXPECT_EQ(b16[118] | b16[119] << 8, 65535);
  EXPECT_EQ(e16.min, v.values.front());
  EXPECT_EQ(e16.max, v.values.back());
  EXPECT_DOUBLE_EQ(e8.code(e8.max), 255.0);
  EXPECT_DOUBLE_EQ(e16.code((e16.min + e16.max) / 2), 32767.5);
}

TEST_F(IoTest, WriteRawRoundsEachValueToTheNearestCode) {
  Volume v;
  v.dims = {5, 1, 1};
  v.values = {0.0f, 1.0f, 1.4f, 1.6f, 255.0f};  // scale 1: codes are the values rounded
  write_raw(v, path("r.raw"), ScalarType::uint8);
  EXPECT_EQ(read_bytes(path("r.raw")), (std::vector<unsigned char>{0, 1, 1, 2, 255}));
}

TEST_F(IoTest, WriteRawConstantFieldStoresCodeZero) {
  Volume v;
  v.dims = {2, 2, 2};
  v.values.assign(8, 3.5f);
  const RawEncoding e = write_raw(v, path("c.raw"), ScalarType::uint16);
  EXPECT_EQ(read_bytes(path("c.raw")), std::vector<unsigned char>(16, 0));
  EXPECT_EQ(e.code(3.5), 0.0);
}

TEST_F(IoTest, WriteRawIntegerTypeRejectsNanAndLeavesNoFile) {
  Volume v = sample_volume();
  v.values[7] = std::numeric_limits<float>::quiet_NaN();
  EXPECT_CONTAINS(io_error_of([&] { write_raw(v, path("n.raw"), ScalarType::uint16); }), "(x,y,z) = (2,1,0)");
  EXPECT_TRUE(entries().empty());
}

// The name carries the layout, so read_volume needs no overrides; it reads back the codes.
TEST_F(IoTest, WriteRawUint16NamedByConventionReadsBackThroughReadVolume) {
  const Volume v = sample_volume();
  const std::string p = path("sample_5x4x3_uint16.raw");
  const RawEncoding e = write_raw(v, p, ScalarType::uint16);
  const Volume back = read_volume(VolumeSpec{p, std::nullopt, std::nullopt});
  EXPECT_EQ(back.dims, v.dims);
  ASSERT_EQ(back.values.size(), v.values.size());
  for (size_t i = 0; i < v.values.size(); ++i) EXPECT_EQ(back.values[i], std::round(e.code(v.values[i]))) << i;
}

TEST_F(IoTest, WriteRawEveryTypeRoundTripsThroughReadRaw) {
  const Volume v = sample_volume();
  for (const ScalarType t :
       {ScalarType::uint8, ScalarType::uint16, ScalarType::int16, ScalarType::float32, ScalarType::float64}) {
    const std::string p = path("v.raw");
    const RawEncoding e = write_raw(v, p, t);
    EXPECT_EQ(fs::file_size(p), 60u * static_cast<size_t>(scalar_type_size(t))) << scalar_type_name(t);
    const Volume back = read_raw(p, RawLayout{v.dims, t});
    for (size_t i = 0; i < v.values.size(); ++i)
      EXPECT_EQ(back.values[i], e.is_mapped() ? std::round(e.code(v.values[i])) : v.values[i])
          << scalar_type_name(t) << " " << i;
  }
  const RawEncoding e = raw_encoding(v, ScalarType::int16);
  EXPECT_EQ(e.code(e.min), -32768.0);
  EXPECT_NEAR(e.code(e.max), 32767.0, 1e-9);
}

TEST_F(IoTest, WritersRejectAVolumeWhoseValuesDoNotMatchItsDims) {
  Volume v = sample_volume();
  v.values.pop_back();
  EXPECT_CONTAINS(io_error_of([&] { write_raw(v, path("a.raw"), ScalarType::float32); }), "59 values");
  EXPECT_CONTAINS(io_error_of([&] { write_raw(v, path("a.raw"), ScalarType::uint16); }), "59 values");
  EXPECT_CONTAINS(io_error_of([&] { write_hdf5(v, path("a.h5")); }), "59 values");
  EXPECT_TRUE(entries().empty());
}

TEST_F(IoTest, WritingIntoAMissingDirectoryThrowsAndLeavesNoFile) {
  const std::string missing = path("no/such/dir");
  const Volume v = sample_volume();
  Mesh m;
  m.positions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
  m.triangles = {{0, 1, 2}};
  EXPECT_CONTAINS(io_error_of([&] { write_raw(v, missing + "/v.raw", ScalarType::float32); }), "does not exist");
  EXPECT_CONTAINS(io_error_of([&] { write_hdf5(v, missing + "/v.h5"); }), "does not exist");
  EXPECT_CONTAINS(io_error_of([&] { write_ply(m, missing + "/m.ply"); }), missing + "/m.ply");
  EXPECT_CONTAINS(io_error_of([&] { AtomicFile f(path("file/x")); }), "does not exist");
  EXPECT_TRUE(entries().empty());
}

// Sets or clears a directory's immutable attribute (chattr +i), which holds even for root.
bool set_immutable(const std::string& dir, bool on) {
  const int fd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (fd < 0) return false;
  int flags = 0;
  bool ok = ::ioctl(fd, FS_IOC_GETFLAGS, &flags) == 0;
  if (ok) {
    flags = on ? (flags | FS_IMMUTABLE_FL) : (flags & ~FS_IMMUTABLE_FL);
    ok = ::ioctl(fd, FS_IOC_SETFLAGS, &flags) == 0;
  }
  ::close(fd);
  return ok;
}

// A directory the process may not write into: by its permissions for a user, by the immutable
// attribute for root (whom permissions do not stop).
TEST_F(IoTest, WritingIntoAReadOnlyDirectoryThrows) {
  fs::create_directory(path("ro"));
  if (::geteuid() == 0) {
    if (!set_immutable(path("ro"), true)) GTEST_SKIP() << "as root, and the file system refuses chattr +i here";
  } else {
    fs::permissions(path("ro"), fs::perms::owner_read | fs::perms::owner_exec);
  }
  const std::string message = io_error_of([&] { AtomicFile f(path("ro/x.ply")); });
  if (::geteuid() == 0) set_immutable(path("ro"), false);
  fs::permissions(path("ro"), fs::perms::owner_all);
  EXPECT_CONTAINS(message, "not writable");
  EXPECT_TRUE(fs::is_empty(path("ro")));
}

// ---------------------------------------------------------------- AtomicFile

TEST_F(IoTest, AtomicFileDestroyedWithoutCommitLeavesNoFile) {
  const std::string p = path("partial.bin");
  {
    AtomicFile f(p);
    f.write("abc", 3);
    EXPECT_TRUE(fs::exists(f.temp_path()));
    EXPECT_EQ(fs::path(f.temp_path()).parent_path(), dir_);
    EXPECT_FALSE(fs::exists(p));
  }
  EXPECT_TRUE(entries().empty());
}

TEST_F(IoTest, AtomicFileCommitReplacesTheTargetAndRemovesTheTemporary) {
  const std::string p = path("done.bin");
  write_values(p, std::vector<uint8_t>{9, 9, 9, 9, 9});
  {
    AtomicFile f(p);
    f.write("xyz", 3);
    EXPECT_EQ(read_bytes(p).size(), 5u);  // the old file stays intact until commit
    f.commit();
    EXPECT_THROW(f.write("more", 4), IoError);
  }
  EXPECT_EQ(read_bytes(p), (std::vector<unsigned char>{'x', 'y', 'z'}));
  EXPECT_EQ(entries(), (std::vector<std::string>{"done.bin"}));
}

// A region appended and then filled on several threads at once, out of order, in blocks that
// straddle no boundary in particular: the file holds the bytes before it, the region's bytes in
// their places, and what was written after it; writing outside the regions made is refused.
TEST_F(IoTest, AtomicFileRegionsAreFilledOnSeveralThreadsBetweenOrdinaryWrites) {
  const std::string p = path("regions.bin");
  std::vector<unsigned char> expected{'h', 'e', 'a', 'd'};
  const size_t n = 1000003;
  {
    AtomicFile f(p);
    f.write("head", 4);
    const uint64_t at = f.append_region(n);
    EXPECT_EQ(at, 4u);
    EXPECT_EQ(f.size(), 4 + n);
    std::vector<unsigned char> bytes(n);
    for (size_t i = 0; i < n; ++i) bytes[i] = static_cast<unsigned char>(i * 7 + i / 251);
    const size_t block = 65537, blocks = (n + block - 1) / block;
    std::vector<std::thread> threads;
    for (size_t t = 0; t < 3; ++t)
      threads.emplace_back([&, t] {
        for (auto b = static_cast<int64_t>(blocks - 1 - t); b >= 0; b -= 3) {  // last block first
          const size_t begin = static_cast<size_t>(b) * block, end = std::min(n, begin + block);
          f.write_region(at + begin, bytes.data() + begin, end - begin);
        }
      });
    for (std::thread& th : threads) th.join();
    EXPECT_CONTAINS(io_error_of([&] { f.write_region(at + n - 1, "xy", 2); }), "past the regions appended");
    f.write("tail", 4);
    expected.insert(expected.end(), bytes.begin(), bytes.end());
    expected.insert(expected.end(), {'t', 'a', 'i', 'l'});
    f.commit();
  }
  EXPECT_EQ(read_bytes(p), expected);
}

// Of each page of the file's first BYTES, whether the page cache holds it (mincore's bit 0): mapped,
// not read, so that looking touches no page.
std::vector<unsigned char> pages_in_cache(const std::string& file, size_t bytes) {
  std::vector<unsigned char> resident((bytes + 4095) / 4096);
  const int fd = ::open(file.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) throw std::runtime_error(file + ": cannot open");
  void* map = ::mmap(nullptr, bytes, PROT_READ, MAP_SHARED, fd, 0);
  ::close(fd);
  if (map == MAP_FAILED) throw std::runtime_error(file + ": cannot map");
  const int looked = ::mincore(map, bytes, resident.data());
  ::munmap(map, bytes);
  if (looked != 0) throw std::runtime_error(file + ": mincore failed");
  return resident;
}

// Why direct writes into DIR would not leave its page cache alone ("" where they do): 64 KB written
// so, then looked for.
std::string no_direct_writes_in(const std::string& dir) {
  const std::string probe = dir + "/probe.bin";
  const int fd = ::open(probe.c_str(), O_WRONLY | O_CREAT | O_DIRECT | O_CLOEXEC, 0644);
  if (fd < 0) return "the file system of " + dir + " takes no O_DIRECT: " + std::strerror(errno);
  const auto block = detail::make_page_aligned<unsigned char>(size_t{64} << 10);
  std::memset(block.get(), 7, size_t{64} << 10);
  const bool written = ::pwrite(fd, block.get(), size_t{64} << 10, 0) == (ssize_t{64} << 10);
  ::close(fd);
  const std::vector<unsigned char> probed = pages_in_cache(probe, size_t{64} << 10);
  std::filesystem::remove(probe);
  if (!written || std::any_of(probed.begin(), probed.end(), [](unsigned char r) { return (r & 1) != 0; }))
    return "the file system of " + dir + " takes no direct write past its page cache";
  return "";
}

// A large region's whole pages go past the page cache (O_DIRECT) and its partial pages through it,
// whether a piece is copied from the caller's bytes (write_region) or encoded in place
// (fill_region): filled on several threads, out of order, in pieces of odd sizes at odd offsets
// (large ones, ones of about 64 KB whose whole pages may or may not be enough for a direct write,
// small ones), the file holds every byte in its place, and where the file system takes direct
// writes, most of its pages are not in the page cache once it is finished (the direct writes never
// put them there). A piece larger than fill_region takes is refused.
TEST_F(IoTest, AtomicFileLargeRegionsGoPastThePageCacheWithTheSameBytes) {
  const size_t n = (size_t{9} << 20) + 4099;
  std::vector<unsigned char> bytes(n);
  for (size_t i = 0; i < n; ++i) bytes[i] = static_cast<unsigned char>(i * 11 + i / 4091);
  // [begin, end): at most one region piece each for fill_region; write_region's first is more
  // than two (copied into the writer's buffers a piece at a time).
  std::vector<std::pair<size_t, size_t>> pieces[2];
  for (const bool fill : {false, true})
    for (size_t at = 0, k = 0; at < n; ++k) {
      const size_t most = k == 0 && !fill ? 2 * AtomicFile::kRegionPieceBytes + 12345 : AtomicFile::kRegionPieceBytes;
      const size_t length = std::min({n - at, most - k % 2,
                                      k % 4 == 0   ? most - k
                                      : k % 4 == 1 ? 852001 + 37 * k
                                      : k % 4 == 2 ? 70001 - 7 * k
                                                   : 1000 + k});
      pieces[fill].emplace_back(at, at + length);
      at += length;
    }
  std::vector<unsigned char> expected{'h', 'e', 'a', 'd', 'e', 'r'};  // the region starts 6 bytes into a page
  expected.insert(expected.end(), bytes.begin(), bytes.end());
  expected.insert(expected.end(), {'t', 'a', 'i', 'l'});
  const std::string no_direct = no_direct_writes_in(dir_.string());
  for (const bool fill : {false, true}) {
    SCOPED_TRACE(fill ? "fill_region" : "write_region");
    const std::string p = path(fill ? "filled_regions.bin" : "large_regions.bin");
    std::vector<unsigned char> resident;
    {
      AtomicFile f(p);
      f.write("header", 6);
      const uint64_t at = f.append_region(n);
      std::atomic<size_t> taken{0};
      std::vector<std::thread> threads;
      for (int t = 0; t < 3; ++t)
        threads.emplace_back([&] {
          for (size_t i; (i = taken++) < pieces[fill].size();) {
            const auto [begin, end] = pieces[fill][pieces[fill].size() - 1 - i];  // the last piece first
            if (fill)
              f.fill_region(at + begin, end - begin, [&, begin = begin, end = end](unsigned char* out) {
                std::copy(bytes.begin() + static_cast<std::ptrdiff_t>(begin),
                          bytes.begin() + static_cast<std::ptrdiff_t>(end), out);
              });
            else
              f.write_region(at + begin, bytes.data() + begin, end - begin);
          }
        });
      for (std::thread& th : threads) th.join();
      if (fill) {
        EXPECT_THROW(f.fill_region(at, AtomicFile::kRegionPieceBytes + 1, [](unsigned char*) {}), std::logic_error);
      }
      f.write("tail", 4);
      f.finish();
      resident = pages_in_cache(f.temp_path(), 6 + n + 4);
      f.commit();
    }
    EXPECT_TRUE(read_bytes(p) == expected) << p << " differs from the bytes written";
    if (!no_direct.empty()) continue;
    const auto cached = std::count_if(resident.begin(), resident.end(), [](unsigned char r) { return (r & 1) != 0; });
    EXPECT_LT(cached, static_cast<std::ptrdiff_t>(resident.size() / 10)) << "of " << resident.size() << " pages";
  }
  if (!no_direct.empty()) GTEST_SKIP() << no_direct;
}

// Direct appends (io/file/direct_appends.h) write the bytes they were given, past the page cache
// or through it: pieces of odd sizes across several of its buffers, overwrites of bytes on disk,
// in the buffer being filled and across the two, and appends after a drain, from an aligned
// offset and from an unaligned one.
TEST_F(IoTest, DirectAppendsWriteWhatTheyWereGivenWithOrWithoutThePageCache) {
  for (const bool direct : {false, true}) {
    for (const size_t total : {size_t{3} << 20, (size_t{3} << 20) + 4099}) {
      SCOPED_TRACE(std::string(direct ? "direct" : "buffered") + ", " + std::to_string(total) + " bytes");
      const std::string p = path("appends.bin");
      const int buffered = ::open(p.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
      ASSERT_GE(buffered, 0);
      const int fd = direct ? ::open(p.c_str(), O_WRONLY | O_DIRECT | O_CLOEXEC) : -1;
      if (direct && fd < 0) {
        ::close(buffered);
        GTEST_SKIP() << "the file system of " << dir_ << " takes no O_DIRECT: " << std::strerror(errno);
      }
      std::vector<unsigned char> expected(total);
      for (size_t i = 0; i < total; ++i) expected[i] = static_cast<unsigned char>(i * 13 + i / 4093);
      {
        DirectAppends appends(fd, buffered);
        const size_t half = total / 2;
        for (size_t at = 0, piece = 1; at < half; at += piece, piece = piece * 3 % 70001 + 1)
          ASSERT_EQ(appends.append(expected.data() + at, std::min(piece, half - at)), 0);
        ASSERT_EQ(appends.drain(), 0);  // the second half starts aligned at 3 MiB, unaligned at 3 MiB + 4099
        for (size_t at = half, piece = 7; at < total; at += piece, piece = piece * 5 % 300007 + 1)
          ASSERT_EQ(appends.append(expected.data() + at, std::min(piece, total - at)), 0);
        EXPECT_EQ(appends.size(), total);
        const std::vector<std::pair<size_t, size_t>> patches{
            {0, 1000}, {(size_t{1} << 20) - 10, 20}, {total - 5000, 4000}, {total - 3, 3}, {(size_t{2} << 20) - 1, 2}};
        for (const auto& [at, bytes] : patches) {
          for (size_t i = at; i < at + bytes; ++i) expected[i] = static_cast<unsigned char>(~expected[i]);
          ASSERT_EQ(appends.overwrite(at, expected.data() + at, bytes), 0);
        }
        ASSERT_EQ(appends.drain(), 0);
        EXPECT_EQ(appends.direct(), direct);
      }
      if (fd >= 0) ::close(fd);
      ::close(buffered);
      EXPECT_EQ(read_bytes(p), expected);
    }
  }
}

// Appends MEGABYTES of 1 MB each, then drains: the first error either met, or 0.
int append_and_drain(DirectAppends& appends, int megabytes) {
  const std::vector<unsigned char> bytes(size_t{1} << 20, 7);
  int err = 0;
  for (int i = 0; i < megabytes && err == 0; ++i) err = appends.append(bytes.data(), bytes.size());
  return err != 0 ? err : appends.drain();
}

// A write the writer thread fails (here: a descriptor not open for writing) is reported by the
// append or the drain after it, with its errno.
TEST_F(IoTest, DirectAppendsReportAFailedWriteByTheirWriterThread) {
  const std::string p = path("refused.bin");
  write_values(p, std::vector<uint8_t>{1});
  const int read_only = ::open(p.c_str(), O_RDONLY | O_CLOEXEC);
  ASSERT_GE(read_only, 0);
  {
    DirectAppends appends(-1, read_only);
    EXPECT_EQ(append_and_drain(appends, 3), EBADF);
  }
  ::close(read_only);
}

// A region's writer thread (io/file/region_writes.h) writes what it is handed: a write it fails
// (here: a descriptor not open for writing) is reported by the next take() and by drain(), with
// its errno, and what is handed over after it is dropped; a direct write the kernel refuses
// (EINVAL: here bytes not aligned in memory) goes through the page cache with the same bytes, as
// every write after it; a writer destroyed with writes not made drops them.
TEST_F(IoTest, RegionWritesReportAFailureAndFallBackWhereDirectWritesAreRefused) {
  constexpr size_t kPiece = size_t{256} << 10;
  const std::string p = path("region_writes.bin");
  write_values(p, std::vector<uint8_t>{1});
  {
    const int read_only = ::open(p.c_str(), O_RDONLY | O_CLOEXEC);
    ASSERT_GE(read_only, 0);
    {
      RegionWrites writes(read_only, read_only, kPiece);
      int err = 0;
      unsigned char* buffer = writes.take(err);
      ASSERT_NE(buffer, nullptr);
      std::memset(buffer, 3, kPiece);
      writes.submit(buffer, buffer, kPiece, 0);
      EXPECT_EQ(writes.drain(), EBADF);
      EXPECT_EQ(writes.take(err), nullptr);
      EXPECT_EQ(err, EBADF);
      EXPECT_EQ(writes.drain(), EBADF) << "reported once only";
    }
    ::close(read_only);
  }
  const int buffered = ::open(p.c_str(), O_WRONLY | O_TRUNC | O_CLOEXEC);
  const int direct = ::open(p.c_str(), O_WRONLY | O_DIRECT | O_CLOEXEC);
  ASSERT_GE(buffered, 0);
  if (direct < 0) {
    ::close(buffered);
    GTEST_SKIP() << "the file system of " << dir_ << " takes no O_DIRECT: " << std::strerror(errno);
  }
  std::vector<unsigned char> expected(3 * kPiece);
  bool refused = false;
  {
    RegionWrites writes(direct, buffered, kPiece);
    for (size_t k = 0; k < 3; ++k) {  // the second from one byte into its buffer: refused direct
      int err = 0;
      unsigned char* buffer = writes.take(err);
      ASSERT_NE(buffer, nullptr) << err;
      unsigned char* from = buffer + (k == 1 ? 1 : 0);
      for (size_t i = 0; i < kPiece; ++i) from[i] = expected[k * kPiece + i] = static_cast<unsigned char>(i * 5 + k);
      writes.submit(buffer, from, kPiece, k * kPiece);
    }
    EXPECT_EQ(writes.drain(), 0);
    refused = !writes.direct();
  }
  EXPECT_TRUE(read_bytes(p) == expected) << p << " differs from the bytes handed over";
  {
    RegionWrites writes(direct, buffered, kPiece);
    for (int k = 0; k < 2; ++k) {
      int err = 0;
      unsigned char* buffer = writes.take(err);
      ASSERT_NE(buffer, nullptr) << err;
      std::memset(buffer, 9, kPiece);
      writes.submit(buffer, buffer, kPiece, (3 + k) * kPiece);
    }
  }  // destroyed without a drain: ends, whatever it wrote of the two
  ::close(direct);
  ::close(buffered);
  EXPECT_TRUE(std::equal(expected.begin(), expected.end(), read_bytes(p).begin()));
  if (!refused) GTEST_SKIP() << "the file system of " << dir_ << " took a direct write from memory one byte off a page";
}

// A region's direct write that fails on the writer thread (here: past a file size limit, EFBIG)
// fails the file's finish() and every commit() after it: the target is never made from a file
// missing those bytes.
TEST_F(IoTest, AFailedRegionWriteFailsEveryCommitAfterIt) {
  const std::string p = path("limited.bin");
  const size_t n = size_t{8} << 20, piece = size_t{1} << 20;
  const std::vector<unsigned char> bytes(piece, 5);
  {
    AtomicFile f(p);
    const uint64_t at = f.append_region(n);  // at 0: every piece whole pages, all handed over
    {
      const testing::FileSizeLimit limit(2 << 20);  // writes past 2 MB fail
      try {
        for (size_t k = 0; k < n / piece; ++k) f.write_region(at + k * piece, bytes.data(), piece);
      } catch (const IoError&) {  // a piece handed over after the failure was seen
      }
      EXPECT_CONTAINS(io_error_of([&] { f.finish(); }), "write failed");
    }
    EXPECT_CONTAINS(io_error_of([&] { f.commit(); }), "write failed");
    EXPECT_CONTAINS(io_error_of([&] { f.commit(); }), "write failed");
  }
  EXPECT_FALSE(std::filesystem::exists(p));
  EXPECT_EQ(entries(), std::vector<std::string>{}) << "the temporary is left behind";
}

// Every few MB written, the appends' own thread makes them durable while the caller goes on: a
// large file's commit then waits for its last few MB alone (io/file/direct_appends.h). Here the
// syncs are seen before any drain: 25 MB appended, at least 16 MB of them synced in time.
TEST_F(IoTest, DirectAppendsMakeWhatTheyWroteDurableWhileTheCallerGoesOn) {
  const std::string p = path("synced.bin");
  const int buffered = ::open(p.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  ASSERT_GE(buffered, 0);
  {
    DirectAppends appends(-1, buffered);
    const std::vector<unsigned char> bytes(size_t{1} << 20, 5);
    for (int i = 0; i < 25; ++i) ASSERT_EQ(appends.append(bytes.data(), bytes.size()), 0);
    // A deadline, not a timing: the syncs take milliseconds.
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(30);
    while (appends.synced() < (uint64_t{16} << 20) && std::chrono::steady_clock::now() < deadline)
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    EXPECT_GE(appends.synced(), uint64_t{16} << 20);
    EXPECT_LE(appends.synced(), uint64_t{25} << 20);
    ASSERT_EQ(appends.drain(), 0);
  }
  ::close(buffered);
  EXPECT_EQ(std::filesystem::file_size(p), size_t{25} << 20);
}

// A sync the appends' thread fails (here: /dev/null, which takes writes but no fdatasync) is
// reported by the drain, with its errno: the file's own fsync after it may no longer report it.
TEST_F(IoTest, DirectAppendsReportAFailedSyncByTheDrain) {
  const int null = ::open("/dev/null", O_WRONLY | O_CLOEXEC);
  ASSERT_GE(null, 0);
  {
    DirectAppends appends(-1, null);
    EXPECT_EQ(append_and_drain(appends, 12), EINVAL);
  }
  ::close(null);
}

// A store's file takes its appends past the page cache: the same bytes, the same file, as through
// it, with its header written last, and a commit as any other output's.
TEST_F(IoTest, AtomicFileWithDirectAppendsHoldsWhatABufferedOneHolds) {
  std::vector<unsigned char> bytes((size_t{5} << 20) + 333);
  for (size_t i = 0; i < bytes.size(); ++i) bytes[i] = static_cast<unsigned char>(i * 31 + i / 509);
  for (const AtomicFile::Appends appends : {AtomicFile::Appends::buffered, AtomicFile::Appends::direct}) {
    const std::string p = path(appends == AtomicFile::Appends::direct ? "direct.bin" : "buffered.bin");
    AtomicFile f(p, appends);
    f.write(bytes.data(), 100);
    for (size_t at = 100; at < bytes.size(); at += 65521)
      f.write(bytes.data() + at, std::min<size_t>(65521, bytes.size() - at));
    f.write_at(0, "header", 6);
    f.commit();
  }
  std::vector<unsigned char> expected = bytes;
  std::memcpy(expected.data(), "header", 6);
  EXPECT_EQ(read_bytes(path("buffered.bin")), expected);
  EXPECT_EQ(read_bytes(path("direct.bin")), expected);
  EXPECT_EQ(entries(), (std::vector<std::string>{"buffered.bin", "direct.bin"}));
}

// What a signal's cleanup removes: registered files, and registered folders with every file in
// them (registered or not) where the folder is still a private one of this user's; never a folder
// registered as a file, nor the files of a folder another mode makes shared, nor what is no longer
// registered.
TEST_F(IoTest, TemporariesRemovedAtOnceAreTheRegisteredOnesAndTheFilesOfPrivateFolders) {
  namespace fs = std::filesystem;
  const auto make_folder = [&](const std::string& name, fs::perms mode) {
    const std::string dir = path(name);
    fs::create_directory(dir);
    fs::permissions(dir, mode);
    write_bytes(dir + "/a", "a", 1);
    write_bytes(dir + "/b", "b", 1);
    return dir;
  };
  const std::string mine = make_folder("mine", fs::perms::owner_all);
  const std::string shared =
      make_folder("shared", fs::perms::owner_all | fs::perms::group_read | fs::perms::group_exec);
  const std::string as_file = make_folder("as_file", fs::perms::owner_all);
  const std::string gone = make_folder("gone", fs::perms::owner_all);
  write_bytes(path("file"), "f", 1);
  write_bytes(path("left"), "l", 1);
  const std::vector<int> slots{register_temporary_folder(mine),   register_temporary(mine + "/a"),
                               register_temporary_folder(shared), register_temporary(as_file),
                               register_temporary(path("file")),  register_temporary(path("left")),
                               register_temporary_folder(gone)};
  for (const int slot : slots) ASSERT_GE(slot, 0);
  unregister_temporary(slots[5]);
  unregister_temporary(slots[6]);
  remove_temporaries_now();
  for (const int slot : slots) unregister_temporary(slot);
  EXPECT_FALSE(fs::exists(mine));
  EXPECT_FALSE(fs::exists(path("file")));
  EXPECT_TRUE(fs::exists(shared + "/a") && fs::exists(shared + "/b")) << "a folder not private to this user";
  EXPECT_TRUE(fs::exists(as_file + "/a") && fs::exists(as_file + "/b")) << "registered as a file";
  EXPECT_TRUE(fs::exists(path("left")));
  EXPECT_TRUE(fs::exists(gone + "/a") && fs::exists(gone + "/b"));
}

// A transient file (a volume's hierarchy store, read back and removed by the process that wrote
// it) holds the same bytes and is committed the same way, but is never synced: removed, its pages
// are dropped unwritten, while a kept file's were written to the disk by its commit. (What this
// sees is the file's own sync: a sync of its folder alone writes none of its pages.)
TEST_F(IoTest, AtomicFileTransientIsNeverSyncedAndHoldsTheSameBytes) {
  const testing::FolderOnDisk folder("transient");
  std::vector<unsigned char> bytes(size_t{8} << 20);
  for (size_t i = 0; i < bytes.size(); ++i) bytes[i] = static_cast<unsigned char>(i * 13 + i / 4093);
  // Whether the file system says so at all: a file written through the page cache and removed.
  const std::string plain = folder.path() + "/plain.bin";
  write_bytes(plain, bytes.data(), bytes.size());
  const int64_t plain_from = testing::cancelled_write_bytes();
  std::filesystem::remove(plain);
  const int64_t plain_dropped = testing::cancelled_write_bytes() - plain_from;
  if (plain_from < 0 || plain_dropped < static_cast<int64_t>(bytes.size() / 2))
    GTEST_SKIP() << "the file system of " << folder.path() << " does not count the unwritten pages it drops";
  std::map<AtomicFile::Appends, int64_t> dropped;
  for (const AtomicFile::Appends appends : {AtomicFile::Appends::buffered, AtomicFile::Appends::transient}) {
    const std::string p = folder.path() + "/file.bin";
    AtomicFile f(p, appends);
    f.write(bytes.data(), 100);
    f.write(bytes.data() + 100, bytes.size() - 100);
    f.write_at(0, "header", 6);
    f.commit();
    std::vector<unsigned char> expected = bytes;
    std::memcpy(expected.data(), "header", 6);
    EXPECT_EQ(read_bytes(p), expected);
    const int64_t before = testing::cancelled_write_bytes();
    std::filesystem::remove(p);
    dropped[appends] = testing::cancelled_write_bytes() - before;
  }
  EXPECT_TRUE(std::filesystem::is_empty(folder.path()));
  EXPECT_EQ(dropped[AtomicFile::Appends::buffered], 0);
  // Half at least: a writeback that the kernel starts meanwhile may take some of the pages.
  EXPECT_GE(dropped[AtomicFile::Appends::transient], static_cast<int64_t>(bytes.size() / 2))
      << "a plain file dropped " << plain_dropped;
}

// The output policy (io/file/atomic_file.h): what is not a regular file is never replaced, and
// refused before anything is written.
TEST_F(IoTest, AtomicFileRefusesATargetThatIsADirectoryBeforeWriting) {
  fs::create_directory(path("taken"));
  EXPECT_CONTAINS(io_error_of([&] { AtomicFile f(path("taken")); }), "is a directory");
  EXPECT_EQ(entries(), (std::vector<std::string>{"taken"}));
  EXPECT_TRUE(fs::is_directory(path("taken")));
}

TEST_F(IoTest, AtomicFileNeverReplacesAFifo) {
  ASSERT_EQ(::mkfifo(path("pipe").c_str(), 0644), 0) << std::strerror(errno);
  EXPECT_CONTAINS(io_error_of([&] { AtomicFile f(path("pipe")); }), "is a FIFO");
  EXPECT_TRUE(fs::is_fifo(path("pipe")));
  EXPECT_EQ(entries(), (std::vector<std::string>{"pipe"}));
}

// A device node made here (as /dev/null is: character device 1,3), never /dev/null itself.
TEST_F(IoTest, AtomicFileNeverReplacesADeviceNode) {
  if (::geteuid() != 0) GTEST_SKIP() << "mknod of a device needs root";
  ASSERT_EQ(::mknod(path("null").c_str(), S_IFCHR | 0666, makedev(1, 3)), 0) << std::strerror(errno);
  EXPECT_CONTAINS(io_error_of([&] { AtomicFile f(path("null")); }), "is a character device");
  EXPECT_TRUE(fs::is_character_file(path("null")));
  EXPECT_EQ(entries(), (std::vector<std::string>{"null"}));
}

TEST_F(IoTest, AtomicFileFollowsALinkAndReplacesTheFileItNamesInItsOwnDirectory) {
  fs::create_directory(path("real"));
  write_values(path("real/mesh.ply"), std::vector<uint8_t>{1, 2, 3});
  fs::create_symlink("real/mesh.ply", path("link.ply"));  // relative: resolved from the link's folder
  {
    AtomicFile f(path("link.ply"));
    EXPECT_EQ(fs::path(f.temp_path()).parent_path(), fs::path(path("real")));
    f.write("xyz", 3);
    f.commit();
  }
  EXPECT_TRUE(fs::is_symlink(path("link.ply")));
  EXPECT_EQ(read_bytes(path("real/mesh.ply")), (std::vector<unsigned char>{'x', 'y', 'z'}));
  EXPECT_EQ(entries(), (std::vector<std::string>{"link.ply", "real"}));
  EXPECT_TRUE(fs::exists(path("real/mesh.ply")));
  EXPECT_EQ(std::distance(fs::directory_iterator(path("real")), fs::directory_iterator()), 1);

  // A dangling link: the file it names is created. A link to a FIFO: refused. A loop: refused.
  fs::create_symlink(path("real/new.ply"), path("dangling.ply"));
  {
    AtomicFile f(path("dangling.ply"));
    f.write("n", 1);
    f.commit();
  }
  EXPECT_TRUE(fs::is_symlink(path("dangling.ply")));
  EXPECT_EQ(read_bytes(path("real/new.ply")), (std::vector<unsigned char>{'n'}));
  ASSERT_EQ(::mkfifo(path("real/pipe").c_str(), 0644), 0);
  fs::create_symlink("real/pipe", path("to_pipe"));
  EXPECT_CONTAINS(io_error_of([&] { AtomicFile f(path("to_pipe")); }), "a FIFO");
  fs::create_symlink("loop_b", path("loop_a"));
  fs::create_symlink("loop_a", path("loop_b"));
  EXPECT_CONTAINS(io_error_of([&] { AtomicFile f(path("loop_a")); }), "symbolic links");
}

TEST_F(IoTest, AnOutputThatIsAnInputOrAnotherOutputIsRefused) {
  write_values(path("in.raw"), std::vector<uint8_t>{1, 2, 3});
  fs::create_hard_link(path("in.raw"), path("hard.raw"));
  fs::create_symlink(path("in.raw"), path("soft.raw"));
  for (const char* same : {"in.raw", "hard.raw", "soft.raw"})
    EXPECT_CONTAINS(io_error_of([&] {
                      check_outputs({{"INPUT", path("in.raw")}}, {{"-o", path(same)}});
                    }),
                    "is the same file as INPUT")
        << same;
  // FILE.h5:/dataset names FILE.h5.
  write_values(path("v.h5"), std::vector<uint8_t>{0});
  EXPECT_CONTAINS(io_error_of([&] {
                    check_outputs({{"INPUT", path("v.h5") + ":/volume"}}, {{"OUTPUT", path("v.h5")}});
                  }),
                  "is the same file as INPUT");
  // Two outputs, existing or not, through a link or not.
  EXPECT_CONTAINS(io_error_of([&] {
                    check_outputs({}, {{"-o", path("m.ply")}, {"--report", path("./m.ply")}});
                  }),
                  "--report " + path("./m.ply") + ": is the same file as -o");
  EXPECT_CONTAINS(io_error_of([&] {
                    check_outputs({}, {{"-o", path("soft.raw")}, {"--report", path("in.raw")}});
                  }),
                  "is the same file as -o");
  // Distinct files pass, and a missing input is left to its reader.
  EXPECT_NO_THROW(check_outputs({{"INPUT", path("in.raw")}, {"INPUT", path("missing.raw")}},
                                {{"-o", path("m.ply")}, {"--report", path("m.json")}, {"--csv", ""}}));
  EXPECT_EQ(read_bytes(path("in.raw")), (std::vector<unsigned char>{1, 2, 3}));
}

// ---------------------------------------------------------------- PLY

struct ParsedPly {
  std::vector<std::string> header;
  Mesh mesh;
  std::vector<uint8_t> face_counts;
  size_t trailing_bytes = 0;
};

template <typename T>
T take_le(const std::vector<unsigned char>& bytes, size_t& at) {
  std::array<unsigned char, sizeof(T)> b{};
  for (size_t i = 0; i < sizeof(T); ++i) b[i] = bytes.at(at + i);
  at += sizeof(T);
  if constexpr (std::endian::native == std::endian::big) std::reverse(b.begin(), b.end());
  return std::bit_cast<T>(b);
}

ParsedPly parse_ply(const std::string& path, size_t vertices, size_t faces) {
  const auto bytes = read_bytes(path);
  const std::string text(bytes.begin(), bytes.end());
  const std::string end = "end_header\n";
  const size_t body = text.find(end) + end.size();
  ParsedPly out;
  std::istringstream head(text.substr(0, body));
  for (std::string line; std::getline(head, line);) out.header.push_back(line);
  size_t at = body;
  for (size_t i = 0; i < vertices; ++i) {
    std::array<float, 3> p{};
    for (float& c : p) c = take_le<float>(bytes, at);
    out.mesh.positions.push_back(p);
  }
  for (size_t i = 0; i < faces; ++i) {
    out.face_counts.push_back(take_le<uint8_t>(bytes, at));
    std::array<uint32_t, 3> t{};
    for (uint32_t& v : t) v = static_cast<uint32_t>(take_le<int32_t>(bytes, at));
    out.mesh.triangles.push_back(t);
  }
  out.trailing_bytes = bytes.size() - at;
  return out;
}

TEST_F(IoTest, PlyWrittenParsesBackToTheSameMesh) {
  Mesh m;
  for (int i = 0; i < 70000; ++i) {  // more than one write block
    const float f = static_cast<float>(i);
    m.positions.push_back({f * 0.5f, -f, f / 3.0f});
  }
  for (uint32_t i = 0; i + 2 < 70000; i += 1) m.triangles.push_back({i, i + 2, i + 1});
  const std::string p = path("mesh.ply");
  write_ply(m, p);
  const ParsedPly ply = parse_ply(p, m.positions.size(), m.triangles.size());
  EXPECT_EQ(ply.header, (std::vector<std::string>{
                            "ply", "format binary_little_endian 1.0", "comment written by isotope",
                            "element vertex 70000", "property float x", "property float y", "property float z",
                            "element face 69998", "property list uchar int vertex_indices", "end_header"}));
  EXPECT_TRUE(ply.mesh.positions == m.positions);
  EXPECT_TRUE(ply.mesh.triangles == m.triangles);
  EXPECT_TRUE(std::all_of(ply.face_counts.begin(), ply.face_counts.end(), [](uint8_t c) { return c == 3; }));
  EXPECT_EQ(ply.trailing_bytes, 0u);
  EXPECT_EQ(entries(), (std::vector<std::string>{"mesh.ply"}));
}

TEST_F(IoTest, PlyOfAnEmptyMeshIsAValidHeaderOnly) {
  const std::string p = path("empty.ply");
  write_ply(Mesh{}, p);
  const ParsedPly ply = parse_ply(p, 0, 0);
  EXPECT_EQ(ply.header.at(3), "element vertex 0");
  EXPECT_EQ(ply.header.at(7), "element face 0");
  EXPECT_EQ(ply.trailing_bytes, 0u);
}

TEST_F(IoTest, PlyWithADanglingIndexIsRejectedAndNotWritten) {
  Mesh m;
  m.positions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
  m.triangles = {{0, 1, 2}, {0, 3, 1}};
  const std::string p = path("bad.ply");
  const std::string msg = io_error_of([&] { write_ply(m, p); });
  EXPECT_CONTAINS(msg, "triangle 1 references vertex 3");
  EXPECT_TRUE(entries().empty());
}

// Dangling indices in the middle and the last of three blocks of triangles (PLY checks its faces
// block by block as it writes them, the other formats all before): every format refuses the mesh,
// names the first, and leaves no file, on any number of threads.
TEST_F(IoTest, EveryFormatRefusesADanglingIndexInAnyBlockAndNamesTheFirst) {
  Mesh m;
  m.positions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
  m.triangles.assign(140000, {0, 1, 2});
  m.triangles[70000] = {0, 5, 1};
  m.triangles[139999] = {9, 0, 1};
  for (const size_t threads : {1, 2, 7}) {
    const tbb::global_control limit(tbb::global_control::max_allowed_parallelism, threads);
    for (const char* name : {"bad.ply", "bad.glb", "bad.vtp", "bad.stl", "bad.obj"}) {
      const std::string msg = io_error_of([&] { write_mesh(m, path(name)); });
      EXPECT_CONTAINS(msg, "triangle 70000 references vertex 5");
      EXPECT_TRUE(entries().empty()) << name << " on " << threads << " threads";
    }
  }
}

// The normals a GLB and a VTP carry are each vertex's own, at its place, on any thread count: the
// writers take them run by run from the threads that finish them (for_each_vertex_normals_run), on
// a mesh of several runs. glTF gives a vertex without a normal +z, VTK 0.
TEST_F(IoTest, GlbAndVtpCarryEveryVertexsNormalAtItsPlace) {
  const Mesh m = extract(generate_linked_tori(193), ExtractOptions{});
  const size_t n = m.positions.size();
  ASSERT_GT(n, 2 * kNormalsPerRun);
  const std::vector<std::array<float, 3>> expected = vertex_normals(m);
  const auto normals_at = [&](const std::vector<unsigned char>& bytes, size_t at) {
    std::vector<std::array<float, 3>> normals(n);
    for (auto& v : normals)
      for (float& c : v) c = take_le<float>(bytes, at);
    return normals;
  };
  for (const size_t threads : {1, 2, 7}) {
    const tbb::global_control limit(tbb::global_control::max_allowed_parallelism, threads);
    write_mesh(m, path("m.glb"));
    write_mesh(m, path("m.vtp"));
    // GLB: a 12-byte header, the JSON chunk (its length, its type, the text), the binary chunk's
    // length and type, then positions, normals and indices.
    const std::vector<unsigned char> glb = read_bytes(path("m.glb"));
    size_t at = 12;
    const size_t json = take_le<uint32_t>(glb, at);
    const std::vector<std::array<float, 3>> in_glb = normals_at(glb, 12 + 8 + json + 8 + 12 * n);
    // VTP: the appended data after "_": the normals' byte count, then the normals.
    const std::vector<unsigned char> vtp = read_bytes(path("m.vtp"));
    const std::string marker = "<AppendedData encoding=\"raw\">\n   _";
    const auto found = std::search(vtp.begin(), vtp.end(), marker.begin(), marker.end());
    ASSERT_NE(found, vtp.end());
    at = static_cast<size_t>(found - vtp.begin()) + marker.size();
    EXPECT_EQ(take_le<uint64_t>(vtp, at), 12 * n);
    const std::vector<std::array<float, 3>> in_vtp = normals_at(vtp, at);
    size_t glb_differ = 0, vtp_differ = 0;
    for (size_t i = 0; i < n; ++i) {
      const bool none = expected[i] == std::array<float, 3>{0, 0, 0};
      glb_differ += in_glb[i] != (none ? std::array<float, 3>{0, 0, 1} : expected[i]);
      vtp_differ += in_vtp[i] != expected[i];
    }
    EXPECT_EQ(glb_differ, 0u) << threads << " threads";
    EXPECT_EQ(vtp_differ, 0u) << threads << " threads";
  }
}

}  // namespace
}  // namespace isotope
