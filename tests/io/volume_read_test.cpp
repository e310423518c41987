// Volumes read: the raw and HDF5 readers agree with each other on the shared volumes, a raw
// file's name gives its layout, and every bad input becomes an IoError naming the file.
#include <gtest/gtest.h>
#include <hdf5.h>
#include <sys/stat.h>

#include <array>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <limits>
#include <string>
#include <utility>
#include <vector>

#include "engine/extract/extract_drivers.h"
#include "io/store/store_reader.h"
#include "io/volume/hdf5_reader.h"
#include "io/volume/raw_reader.h"
#include "io/volume/volume_reader.h"
#include "tests/support/byte_files.h"
#include "tests/support/child_process.h"
#include "tests/support/io_error_of.h"
#include "tests/support/temp_dir_test.h"

namespace isotope {
namespace {

namespace fs = std::filesystem;

using VolumeRead = testing::TempDirTest;
using testing::io_error_of;
using testing::write_values;

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

const fs::path kData = ISOTOPE_TEST_DATA;

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

TEST_F(VolumeRead, RawSizeMismatchNamesFileSizesAndLayout) {
  const std::string p = path("neghip_66x66x66_uint8.raw");
  write_values(p, std::vector<uint8_t>(287495));
  const std::string msg = io_error_of([&] { read_raw(p, *parse_raw_name(p)); });
  EXPECT_CONTAINS(msg, "neghip_66x66x66_uint8.raw");
  EXPECT_CONTAINS(msg, "size 287495 bytes, expected 287496 for 66x66x66 uint8");
}

TEST_F(VolumeRead, RawTruncatedFileIsRejected) {
  const std::string p = path("v_4x4x4_float32.raw");
  write_values(p, std::vector<float>(40));
  const std::string msg = io_error_of([&] { read_raw(p, *parse_raw_name(p)); });
  EXPECT_CONTAINS(msg, p);
  EXPECT_CONTAINS(msg, "size 160 bytes, expected 256");
}

TEST_F(VolumeRead, RawMissingFileIsRejectedByName) {
  const std::string p = path("absent_2x2x2_uint8.raw");
  const std::string msg = io_error_of([&] { read_raw(p, *parse_raw_name(p)); });
  EXPECT_CONTAINS(msg, p);
  EXPECT_CONTAINS(msg, "no such file");
}

TEST_F(VolumeRead, RawDirectoryInsteadOfFileIsRejected) {
  const std::string p = path("dir_2x2x2_uint8.raw");
  fs::create_directory(p);
  EXPECT_CONTAINS(io_error_of([&] { read_raw(p, *parse_raw_name(p)); }), "is a directory");
}

// The input policy (require_regular_file): a FIFO without a writer would block every reader's open
// forever (this test then hangs until ctest's timeout); each reader refuses it by name instead,
// through a link too, and an NRRD header whose detached data file is a FIFO as well.
TEST_F(VolumeRead, NonRegularInputsAreRefused) {
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

TEST_F(VolumeRead, RawNanIsRejectedWithItsCoordinates) {
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

TEST_F(VolumeRead, RawInfinityAndFloat64BeyondFloatRangeAreRejected) {
  const std::string inf = path("inf_2x1x1_float64.raw");
  write_values(inf, std::vector<double>{1.0, -std::numeric_limits<double>::infinity()});
  EXPECT_CONTAINS(io_error_of([&] { read_raw(inf, *parse_raw_name(inf)); }), "(1,0,0)");
  const std::string big = path("big_1x1x2_float64.raw");
  write_values(big, std::vector<double>{1.0, 1e300});
  EXPECT_CONTAINS(io_error_of([&] { read_raw(big, *parse_raw_name(big)); }), "(0,0,1)");
}

TEST_F(VolumeRead, RawDecodesEveryScalarTypeLittleEndianXFastest) {
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

TEST_F(VolumeRead, RawZeroAndOverflowingDimsAreRejected) {
  const std::string p = path("x.raw");
  write_values(p, std::vector<uint8_t>(8));
  EXPECT_CONTAINS(io_error_of([&] { read_raw(p, {{2, 0, 2}, ScalarType::uint8}); }), ">= 1");
  EXPECT_CONTAINS(io_error_of([&] { read_raw(p, {{-2, 2, 2}, ScalarType::uint8}); }), ">= 1");
  const int64_t big = int64_t{1} << 31;
  EXPECT_CONTAINS(io_error_of([&] { read_raw(p, {{big, big, big}, ScalarType::uint8}); }), "too large");
  EXPECT_CONTAINS(io_error_of([&] { read_raw(p, {{big, big, 2}, ScalarType::float64}); }), "too large");
}

// ---------------------------------------------------------------- HDF5 reader

TEST_F(VolumeRead, Hdf5MissingFileIsRejectedByName) {
  const std::string p = path("absent.h5");
  const std::string msg = io_error_of([&] { read_hdf5(p, "/volume"); });
  EXPECT_CONTAINS(msg, p);
  EXPECT_CONTAINS(msg, "no such file");
}

TEST_F(VolumeRead, NonHdf5FileNamedH5IsRejected) {
  const std::string p = path("fake.h5");
  write_values(p, std::vector<uint8_t>(1000, 7));
  const std::string msg = io_error_of([&] { read_hdf5(p, "/volume"); });
  EXPECT_CONTAINS(msg, p);
  EXPECT_CONTAINS(msg, "not an HDF5 file");
  EXPECT_CONTAINS(io_error_of([&] { read_volume({p, {}, {}}); }), "not an HDF5 file");
}

TEST_F(VolumeRead, Hdf5MissingDatasetListsThe3dDatasetsThatExist) {
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

TEST_F(VolumeRead, Hdf5RankOtherThanThreeIsRejected) {
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

TEST_F(VolumeRead, Hdf5NonNumericTypeIsRejected) {
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

TEST_F(VolumeRead, Hdf5NanIsRejectedWithItsCoordinates) {
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

TEST_F(VolumeRead, Hdf5ChunkedGzipUint16ReadsExactlyWithAttributes) {
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

TEST_F(VolumeRead, Hdf5Float64IsRoundedToFloat) {
  const std::string p = path("f64.h5");
  const std::vector<double> v{0.1, 1.0 / 3.0, -2.0, 1e-7, 5, 6, 7, 8};
  {
    H5Builder b(p);
    b.add("/volume", H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, {2, 2, 2}, v.data());
  }
  const Volume vol = read_hdf5(p, "/volume");
  for (size_t i = 0; i < v.size(); ++i) EXPECT_EQ(vol.values[i], static_cast<float>(v[i])) << i;
}

TEST_F(VolumeRead, Hdf5BadSpacingAttributeIsRejected) {
  const std::string p = path("badspacing.h5");
  {
    H5Builder b(p);
    const auto v = iota_floats(8);
    const hid_t ds = b.add("/volume", H5T_IEEE_F32LE, H5T_NATIVE_FLOAT, {2, 2, 2}, v.data());
    b.attribute(ds, "spacing", {1.0, 2.0});
  }
  EXPECT_CONTAINS(io_error_of([&] { read_hdf5(p, "/volume"); }), "'spacing' must hold 3 numbers");
}

TEST_F(VolumeRead, Hdf5ErrorPathsLeaveNoHandleOpen) {
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

// The isotope command links HDF5's static archive (ISOTOPE_ARCHIVES), and a filter plugin links
// the shared library, which then loads beside it: a dataset compressed by a plugin (Debian's
// hdf5-filter-plugin: lz4, bzip2) reads through the command as the same values gzip-compressed.
TEST_F(VolumeRead, Hdf5DatasetsOfFilterPluginsReadThroughTheCommandAsWithGzip) {
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

TEST_F(VolumeRead, ReadVolumeSplitsTheSpecAtTheLastColonSlash) {
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

TEST_F(VolumeRead, ReadVolumeRawUsesOverridesBeforeTheName) {
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

TEST_F(VolumeRead, ReadVolumeAsksForDimsAndTypeWhenTheNameSaysNothing) {
  const std::string p = path("blob.bin");
  write_values(p, std::vector<uint8_t>(8));
  const std::string msg = io_error_of([&] { read_volume({p, {}, {}}); });
  EXPECT_CONTAINS(msg, p);
  EXPECT_CONTAINS(msg, "pass --dims and --type");
  EXPECT_CONTAINS(io_error_of([&] { read_volume({p, std::array<int64_t, 3>{2, 2, 2}, {}}); }), "cannot tell the type");
  EXPECT_EQ(read_volume({p, std::array<int64_t, 3>{2, 2, 2}, ScalarType::uint8}).values.size(), 8u);
}

TEST_F(VolumeRead, ReadVolumeReportsAMissingFileBeforeAskingForALayout) {
  const std::string p = path("typo.bin");
  const std::string msg = io_error_of([&] { read_volume({p, {}, {}}); });
  EXPECT_CONTAINS(msg, p + ": no such file");
  EXPECT_CONTAINS(io_error_of([&] { read_volume({dir_.string(), {}, {}}); }), "is a directory");
  EXPECT_CONTAINS(io_error_of([&] { read_volume({path("gone.h5") + ":/volume", {}, {}}); }), "no such file");
}

}  // namespace
}  // namespace isotope
