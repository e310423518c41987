// Volumes written: the raw and HDF5 writers round-trip exactly, integer types map the range onto
// their codes, and a failed write leaves no file.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <hdf5.h>
#include <linux/fs.h>
#include <sys/ioctl.h>
#include <unistd.h>

#include <cmath>
#include <cstdint>
#include <filesystem>
#include <limits>
#include <string>
#include <vector>

#include "io/file/atomic_file.h"
#include "io/volume/hdf5_reader.h"
#include "io/volume/raw_reader.h"
#include "io/volume/volume_reader.h"
#include "io/volume/volume_writer.h"
#include "tests/support/byte_files.h"
#include "tests/support/io_error_of.h"
#include "tests/support/temp_dir_test.h"

namespace isotope {
namespace {

namespace fs = std::filesystem;

using VolumeWrite = testing::TempDirTest;
using testing::io_error_of;
using testing::read_bytes;
using testing::write_values;

Volume sample_volume() {
  Volume v;
  v.dims = {5, 4, 3};
  v.spacing = {0.5, 2.0, 3.25};
  v.origin = {-1.0, 0.0, 7.5};
  for (int64_t i = 0; i < v.node_count(); ++i) v.values.push_back(static_cast<float>(i) * 0.37f - 4.0f);
  return v;
}

// ---------------------------------------------------------------- writers

TEST_F(VolumeWrite, WriteHdf5ThenReadHdf5RoundTripsExactly) {
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

TEST_F(VolumeWrite, WriteHdf5ReplacesAnExistingFile) {
  const std::string p = path("out.h5");
  write_values(p, std::vector<uint8_t>(100, 1));
  write_hdf5(sample_volume(), p);
  EXPECT_EQ(read_hdf5(p, "/volume").values, sample_volume().values);
  EXPECT_EQ(entries(), (std::vector<std::string>{"out.h5"}));
}

TEST_F(VolumeWrite, WriteRawFloat32ThenReadRawRoundTripsExactly) {
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
TEST_F(VolumeWrite, WriteRawIntegerTypesStretchMinToZeroAndMaxToTheTopCode) {
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

TEST_F(VolumeWrite, WriteRawRoundsEachValueToTheNearestCode) {
  Volume v;
  v.dims = {5, 1, 1};
  v.values = {0.0f, 1.0f, 1.4f, 1.6f, 255.0f};  // scale 1: codes are the values rounded
  write_raw(v, path("r.raw"), ScalarType::uint8);
  EXPECT_EQ(read_bytes(path("r.raw")), (std::vector<unsigned char>{0, 1, 1, 2, 255}));
}

TEST_F(VolumeWrite, WriteRawConstantFieldStoresCodeZero) {
  Volume v;
  v.dims = {2, 2, 2};
  v.values.assign(8, 3.5f);
  const RawEncoding e = write_raw(v, path("c.raw"), ScalarType::uint16);
  EXPECT_EQ(read_bytes(path("c.raw")), std::vector<unsigned char>(16, 0));
  EXPECT_EQ(e.code(3.5), 0.0);
}

TEST_F(VolumeWrite, WriteRawIntegerTypeRejectsNanAndLeavesNoFile) {
  Volume v = sample_volume();
  v.values[7] = std::numeric_limits<float>::quiet_NaN();
  EXPECT_CONTAINS(io_error_of([&] { write_raw(v, path("n.raw"), ScalarType::uint16); }), "(x,y,z) = (2,1,0)");
  EXPECT_TRUE(entries().empty());
}

// The name carries the layout, so read_volume needs no overrides; it reads back the codes.
TEST_F(VolumeWrite, WriteRawUint16NamedByConventionReadsBackThroughReadVolume) {
  const Volume v = sample_volume();
  const std::string p = path("sample_5x4x3_uint16.raw");
  const RawEncoding e = write_raw(v, p, ScalarType::uint16);
  const Volume back = read_volume(VolumeSpec{p, std::nullopt, std::nullopt});
  EXPECT_EQ(back.dims, v.dims);
  ASSERT_EQ(back.values.size(), v.values.size());
  for (size_t i = 0; i < v.values.size(); ++i) EXPECT_EQ(back.values[i], std::round(e.code(v.values[i]))) << i;
}

TEST_F(VolumeWrite, WriteRawEveryTypeRoundTripsThroughReadRaw) {
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

TEST_F(VolumeWrite, WritersRejectAVolumeWhoseValuesDoNotMatchItsDims) {
  Volume v = sample_volume();
  v.values.pop_back();
  EXPECT_CONTAINS(io_error_of([&] { write_raw(v, path("a.raw"), ScalarType::float32); }), "59 values");
  EXPECT_CONTAINS(io_error_of([&] { write_raw(v, path("a.raw"), ScalarType::uint16); }), "59 values");
  EXPECT_CONTAINS(io_error_of([&] { write_hdf5(v, path("a.h5")); }), "59 values");
  EXPECT_TRUE(entries().empty());
}

TEST_F(VolumeWrite, WritingIntoAMissingDirectoryThrowsAndLeavesNoFile) {
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
TEST_F(VolumeWrite, WritingIntoAReadOnlyDirectoryThrows) {
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

}  // namespace
}  // namespace isotope
