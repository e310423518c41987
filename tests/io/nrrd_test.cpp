// The NRRD reader: attached, detached and gzip data agree with the raw reader on the shared
// volumes, geometry fields map to Volume, and every bad input becomes an IoError naming the file.
#include <gtest/gtest.h>
#include <unistd.h>
#include <zlib.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <bit>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iterator>
#include <limits>
#include <string>
#include <vector>

#include "io/volume/nrrd_reader.h"
#include "io/volume/raw_reader.h"
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

const fs::path kData = ISOTOPE_TEST_DATA;
const std::string kNeghip = (kData / "neghip_66x66x66_uint8.raw").string();
const std::string kHydrogen = (kData / "hydrogen_64x64x64_float32.raw").string();

using NrrdTest = testing::TempDirTest;

// "NRRD0004", the field lines, and the blank line that ends the header.
std::string header(const std::vector<std::string>& fields, const std::string& magic = "NRRD0004") {
  std::string text = magic + "\n";
  for (const auto& f : fields) text += f + "\n";
  return text + "\n";
}

// The header of a 3-D volume; EXTRA fields follow the required ones.
std::string volume_header(const std::string& sizes, const std::string& type, const std::string& encoding,
                          const std::vector<std::string>& extra = {}) {
  std::vector<std::string> fields = {"dimension: 3", "sizes: " + sizes, "type: " + type, "encoding: " + encoding};
  fields.insert(fields.end(), extra.begin(), extra.end());
  return header(fields);
}

Volume read_shared_raw(const std::string& raw_path) { return read_raw(raw_path, *parse_raw_name(raw_path)); }

using testing::io_error_of;

// The message read_nrrd gives for a file of TEXT then DATA.
std::string nrrd_error(const std::string& p, const std::string& text, const Bytes& data = {}) {
  write_file(p, text, data);
  return io_error_of([&] { read_nrrd(p); });
}

const Bytes kSmallData = {0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15, 16, 17, 18, 19, 20, 21, 22, 23};
const std::string kSmallHeader = volume_header("2 3 4", "uchar", "raw");

// ---------------------------------------------------------------- shared volumes

TEST_F(NrrdTest, AttachedRawUint8EqualsTheRawFile) {
  const std::string p = path("neghip.nrrd");
  write_file(p, volume_header("66 66 66", "uchar", "raw"), read_bytes(kNeghip));
  const Volume v = read_nrrd(p);
  const Volume raw = read_shared_raw(kNeghip);
  EXPECT_EQ(v.dims, (std::array<int64_t, 3>{66, 66, 66}));
  EXPECT_EQ(v.spacing, (std::array<double, 3>{1, 1, 1}));
  EXPECT_EQ(v.origin, (std::array<double, 3>{0, 0, 0}));
  EXPECT_TRUE(v.values == raw.values);
}

TEST_F(NrrdTest, DetachedHeaderWithAbsoluteDataFileEqualsReadRaw) {
  const std::string p = path("hydrogen.nhdr");
  write_file(p, volume_header("64 64 64", "float", "raw", {"endian: little", "data file: " + kHydrogen}));
  const Volume v = read_nrrd(p);
  EXPECT_EQ(v.dims, (std::array<int64_t, 3>{64, 64, 64}));
  EXPECT_TRUE(v.values == read_shared_raw(kHydrogen).values);
}

TEST_F(NrrdTest, DetachedDataFileIsRelativeToTheHeaderNotTheWorkingDirectory) {
  fs::create_directories(dir_ / "volumes" / "data");
  fs::copy_file(kNeghip, dir_ / "volumes" / "data" / "neghip.raw");
  const std::string p = path("volumes/neghip.nhdr");
  write_file(p, volume_header("66 66 66", "uint8", "raw", {"data file: data/neghip.raw"}));
  EXPECT_TRUE(read_nrrd(p).values == read_shared_raw(kNeghip).values);
}

TEST_F(NrrdTest, GzipFloat32EqualsReadRaw) {
  const std::string p = path("hydrogen.nrrd");
  write_file(p, volume_header("64 64 64", "float", "gzip", {"endian: little"}), gzip(read_bytes(kHydrogen)));
  const Volume v = read_nrrd(p);
  EXPECT_EQ(v.dims, (std::array<int64_t, 3>{64, 64, 64}));
  EXPECT_TRUE(v.values == read_shared_raw(kHydrogen).values);
}

TEST_F(NrrdTest, DetachedGzipDataFileEqualsReadRaw) {
  write_file(path("neghip.raw.gz"), "", gzip(read_bytes(kNeghip)));
  const std::string p = path("neghip.nhdr");
  write_file(p, volume_header("66 66 66", "unsigned char", "gz", {"data file: neghip.raw.gz"}));
  EXPECT_TRUE(read_nrrd(p).values == read_shared_raw(kNeghip).values);
}

// ---------------------------------------------------------------- types and byte order

TEST_F(NrrdTest, BigEndianUint16AndFloat32Decode) {
  const std::string u16 = path("u16.nrrd");
  write_file(u16, volume_header("2 2 1", "ushort", "raw", {"endian: big"}),
             Bytes{0x00, 0x01, 0x01, 0x00, 0xff, 0xff, 0x12, 0x34});
  EXPECT_EQ(read_nrrd(u16).values, (std::vector<float>{1, 256, 65535, 0x1234}));

  const std::vector<float> floats = {0.5f, -3.25f, 1e-20f, 6.5e7f, -0.0f, 42.0f};
  const std::string f32 = path("f32.nrrd");
  write_file(f32, volume_header("1 2 3", "float", "raw", {"endian: big"}), bytes_of(floats, std::endian::big));
  EXPECT_EQ(read_nrrd(f32).values, floats);
}

TEST_F(NrrdTest, EverySupportedTypeDecodesInEitherByteOrder) {
  for (const std::endian order : {std::endian::little, std::endian::big}) {
    const std::string endian = order == std::endian::big ? "endian: big" : "endian: little";
    SCOPED_TRACE(endian);
    const std::string i16 = path("i16.nrrd");
    write_file(i16, volume_header("3 1 1", "signed short int", "raw", {endian}),
               bytes_of(std::vector<int16_t>{-32768, -1, 32767}, order));
    EXPECT_EQ(read_nrrd(i16).values, (std::vector<float>{-32768, -1, 32767}));

    const std::string u16 = path("u16.nrrd");
    write_file(u16, volume_header("1 1 2", "uint16_t", "gzip", {endian}),
               gzip(bytes_of(std::vector<uint16_t>{7, 65000}, order)));
    EXPECT_EQ(read_nrrd(u16).values, (std::vector<float>{7, 65000}));

    const std::string f64 = path("f64.nrrd");
    write_file(f64, volume_header("1 2 1", "double", "raw", {endian}), bytes_of(std::vector<double>{0.1, -2.5}, order));
    EXPECT_EQ(read_nrrd(f64).values, (std::vector<float>{0.1f, -2.5f}));
  }
}

TEST_F(NrrdTest, FirstAxisIsFastest) {
  const std::string p = path("order.nrrd");
  write_file(p, kSmallHeader, kSmallData);
  const Volume v = read_nrrd(p);
  EXPECT_EQ(v.dims, (std::array<int64_t, 3>{2, 3, 4}));
  EXPECT_EQ(v.at(1, 0, 0), 1.0f);
  EXPECT_EQ(v.at(0, 1, 0), 2.0f);
  EXPECT_EQ(v.at(0, 0, 1), 6.0f);
  EXPECT_EQ(v.at(1, 2, 3), 23.0f);
}

// ---------------------------------------------------------------- header syntax

TEST_F(NrrdTest, CommentsKeyValuesCrlfAndFieldSpellingsAreAccepted) {
  const std::string p = path("loose.nrrd");
  const std::string text =
      "NRRD0005\r\n# written by hand\r\nDimension: 3\r\ncontent: a: b\r\nmy key:=my: value\r\n"
      "type: UNSIGNED  CHAR\r\nsizes:  2 3 4 \r\nkinds: domain domain domain\r\nencoding: raw\r\n"
      "byteskip: 0\r\n\r\n";
  write_file(p, text, kSmallData);
  const Volume v = read_nrrd(p);
  EXPECT_EQ(v.dims, (std::array<int64_t, 3>{2, 3, 4}));
  EXPECT_EQ(v.values.back(), 23.0f);
}

TEST_F(NrrdTest, EveryMagicVersionFromOneToFiveIsAccepted) {
  for (char version = '1'; version <= '5'; ++version) {
    const std::string magic = std::string("NRRD000") + version;
    SCOPED_TRACE(magic);
    const std::string p = path("v.nrrd");
    write_file(p, header({"dimension: 3", "sizes: 2 3 4", "type: uchar", "encoding: raw"}, magic), kSmallData);
    EXPECT_EQ(read_nrrd(p).values.size(), kSmallData.size());
  }
}

// ---------------------------------------------------------------- geometry

TEST_F(NrrdTest, SpacingsMapToVolumeSpacing) {
  const std::string p = path("spacings.nrrd");
  write_file(p, volume_header("2 3 4", "uchar", "raw", {"spacings: 0.5 2 3.25"}), kSmallData);
  const Volume v = read_nrrd(p);
  EXPECT_EQ(v.spacing, (std::array<double, 3>{0.5, 2, 3.25}));
  EXPECT_EQ(v.origin, (std::array<double, 3>{0, 0, 0}));
}

TEST_F(NrrdTest, SpaceDirectionsAndOriginMapToSpacingAndOrigin) {
  const std::string p = path("space.nrrd");
  write_file(p,
             volume_header("2 3 4", "uchar", "raw",
                           {"space: right-anterior-superior", "space directions: (0.5,0,0) (0, 2,0) ( 0,0,3.25 )",
                            "space origin: (-1,0,7.5)"}),
             kSmallData);
  const Volume v = read_nrrd(p);
  EXPECT_EQ(v.spacing, (std::array<double, 3>{0.5, 2, 3.25}));
  EXPECT_EQ(v.origin, (std::array<double, 3>{-1, 0, 7.5}));
}

TEST_F(NrrdTest, RotatedSpaceDirectionsKeepOnlyTheirLengths) {
  const std::string p = path("rotated.nrrd");
  write_file(p, volume_header("2 3 4", "uchar", "raw", {"space directions: (0,3,4) (-2,0,0) (0,0,-1.5)"}), kSmallData);
  EXPECT_EQ(read_nrrd(p).spacing, (std::array<double, 3>{5, 2, 1.5}));
}

TEST_F(NrrdTest, BadGeometryFieldsAreRejected) {
  const std::string p = path("geometry.nrrd");
  const auto error_with = [&](const std::string& field) {
    return nrrd_error(p, volume_header("2 3 4", "uchar", "raw", {field}), kSmallData);
  };
  EXPECT_CONTAINS(error_with("spacings: 1 nan 1"), "spacings '1 nan 1' must be 3 finite numbers > 0");
  EXPECT_CONTAINS(error_with("spacings: 1 0 1"), "must be 3 finite numbers > 0");
  EXPECT_CONTAINS(error_with("spacings: 1 1"), "must be 3 finite numbers > 0");
  EXPECT_CONTAINS(error_with("space directions: (1,0,0) none (0,0,1)"), "must be 3 vectors");
  EXPECT_CONTAINS(error_with("space directions: (1,0,0) (0,0,0) (0,0,1)"), "nonzero lengths");
  EXPECT_CONTAINS(error_with("space directions: (1,0) (0,1) (0,0)"), "must be 3 vectors");
  EXPECT_CONTAINS(error_with("space origin: (1,2)"), "space origin '(1,2)'");
  const std::string both = nrrd_error(
      p, volume_header("2 3 4", "uchar", "raw", {"spacings: 1 1 1", "space directions: (1,0,0) (0,1,0) (0,0,1)"}),
      kSmallData);
  EXPECT_CONTAINS(both, "both 'spacings' and 'space directions'");
}

// ---------------------------------------------------------------- skips

TEST_F(NrrdTest, ByteSkipIsHonoured) {
  Bytes junk_then_data = {0xde, 0xad, 0xbe, 0xef, 0x99};
  junk_then_data.insert(junk_then_data.end(), kSmallData.begin(), kSmallData.end());
  const std::string attached = path("skip.nrrd");
  write_file(attached, volume_header("2 3 4", "uchar", "raw", {"byte skip: 5"}), junk_then_data);
  EXPECT_EQ(read_nrrd(attached).values.back(), 23.0f);
  EXPECT_EQ(read_nrrd(attached).values.front(), 0.0f);

  // -1: the data are the last bytes of the file, whatever comes before them.
  write_file(path("with_junk.raw"), "", junk_then_data);
  const std::string at_end = path("at_end.nhdr");
  write_file(at_end, volume_header("2 3 4", "uchar", "raw", {"byte skip: -1", "data file: with_junk.raw"}));
  EXPECT_EQ(read_nrrd(at_end).values.front(), 0.0f);

  // Compressed data skip decompressed bytes.
  const std::string gz = path("skip_gz.nrrd");
  write_file(gz, volume_header("2 3 4", "uchar", "gzip", {"byte skip: 5"}), gzip(junk_then_data));
  EXPECT_EQ(read_nrrd(gz).values.front(), 0.0f);
}

TEST_F(NrrdTest, LineSkipIsHonoured) {
  const std::string p = path("lines.nhdr");
  write_file(path("lines.raw"), "first line\nsecond\n", kSmallData);
  write_file(p, volume_header("2 3 4", "uchar", "raw", {"line skip: 2", "data file: lines.raw"}));
  EXPECT_EQ(read_nrrd(p).values.front(), 0.0f);
  write_file(path("only_lines.raw"), "first line\nsecond\n");
  write_file(p, volume_header("2 3 4", "uchar", "raw", {"line skip: 3", "data file: only_lines.raw"}));
  EXPECT_CONTAINS(io_error_of([&] { read_nrrd(p); }), "lines to skip");
}

TEST_F(NrrdTest, BadSkipsAreRejected) {
  const std::string p = path("skips.nrrd");
  EXPECT_CONTAINS(nrrd_error(p, volume_header("2 3 4", "uchar", "raw", {"byte skip: -2"}), kSmallData),
                  "byte skip '-2' must be an integer >= -1");
  EXPECT_CONTAINS(nrrd_error(p, volume_header("2 3 4", "uchar", "gzip", {"byte skip: -1"}), gzip(kSmallData)),
                  "only allowed with raw encoding");
  EXPECT_CONTAINS(nrrd_error(p, volume_header("2 3 4", "uchar", "raw", {"byte skip: 1000"}), kSmallData),
                  "data truncated: 0 of 24 bytes");
  EXPECT_CONTAINS(nrrd_error(p, volume_header("2 3 4", "uchar", "raw", {"line skip: -1"}), kSmallData),
                  "line skip '-1'");
}

// ---------------------------------------------------------------- rejected headers

TEST_F(NrrdTest, WrongMagicIsRejected) {
  for (const std::string magic : {"NRRD0006", "NRRD0000", "NRRD00041", "nrrd0004", "P5", ""}) {
    SCOPED_TRACE(magic);
    const std::string p = path("magic.nrrd");
    const std::string msg =
        nrrd_error(p, header({"dimension: 3", "sizes: 2 3 4", "type: uchar", "encoding: raw"}, magic), kSmallData);
    EXPECT_CONTAINS(msg, p);
    EXPECT_CONTAINS(msg, "not an NRRD file");
  }
}

TEST_F(NrrdTest, DimensionOtherThanThreeIsRejected) {
  const std::string p = path("flat.nrrd");
  const std::string msg =
      nrrd_error(p, header({"dimension: 2", "sizes: 4 6", "type: uchar", "encoding: raw"}), kSmallData);
  EXPECT_CONTAINS(msg, p);
  EXPECT_CONTAINS(msg, "dimension '2' not supported");
  EXPECT_CONTAINS(nrrd_error(p, header({"dimension: 4", "sizes: 1 2 3 4"}), kSmallData), "dimension '4'");
}

TEST_F(NrrdTest, UnsupportedTypeIsRejectedByName) {
  for (const std::string type : {"int64", "signed char", "int", "uint32", "block"}) {
    SCOPED_TRACE(type);
    const std::string p = path("type.nrrd");
    const std::string msg = nrrd_error(p, volume_header("2 3 4", type, "raw", {"endian: little"}), kSmallData);
    EXPECT_CONTAINS(msg, p);
    EXPECT_CONTAINS(msg, "type '" + type + "' not supported");
  }
}

TEST_F(NrrdTest, TextAndBzip2EncodingsAreRejected) {
  for (const std::string encoding : {"ascii", "text", "hex", "bzip2", "bz2", "zip"}) {
    SCOPED_TRACE(encoding);
    const std::string p = path("encoding.nrrd");
    const std::string msg = nrrd_error(p, volume_header("2 3 4", "uchar", encoding), kSmallData);
    EXPECT_CONTAINS(msg, p);
    EXPECT_CONTAINS(msg, "encoding '" + encoding + "' not supported; expected raw or gzip");
  }
}

TEST_F(NrrdTest, MissingRequiredFieldsAreNamed) {
  const std::string p = path("missing.nrrd");
  EXPECT_CONTAINS(nrrd_error(p, header({"dimension: 3", "type: uchar", "encoding: raw"}), kSmallData),
                  "header has no 'sizes' field");
  EXPECT_CONTAINS(nrrd_error(p, header({"sizes: 2 3 4", "type: uchar", "encoding: raw"}), kSmallData),
                  "no 'dimension' field");
  EXPECT_CONTAINS(nrrd_error(p, header({"dimension: 3", "sizes: 2 3 4", "encoding: raw"}), kSmallData),
                  "no 'type' field");
  EXPECT_CONTAINS(nrrd_error(p, header({"dimension: 3", "sizes: 2 3 4", "type: uchar"}), kSmallData),
                  "no 'encoding' field");
  EXPECT_CONTAINS(nrrd_error(p, volume_header("2 3 2", "short", "raw"), kSmallData),
                  "no 'endian' field, required for int16");
}

TEST_F(NrrdTest, MalformedFieldValuesAreRejected) {
  const std::string p = path("malformed.nrrd");
  EXPECT_CONTAINS(nrrd_error(p, volume_header("2 3", "uchar", "raw"), kSmallData),
                  "sizes '2 3' must be 3 integers >= 1");
  EXPECT_CONTAINS(nrrd_error(p, volume_header("2 0 4", "uchar", "raw"), kSmallData), "must be 3 integers >= 1");
  EXPECT_CONTAINS(nrrd_error(p, volume_header("2 x 4", "uchar", "raw"), kSmallData), "must be 3 integers >= 1");
  EXPECT_CONTAINS(nrrd_error(p, volume_header("2 3 4", "short", "raw", {"endian: middle"}), kSmallData),
                  "endian 'middle' must be little or big");
  EXPECT_CONTAINS(nrrd_error(p, volume_header("2 3 4", "uchar", "raw", {"no separator"}), kSmallData),
                  "header line 'no separator' is not 'field: value'");
  EXPECT_CONTAINS(nrrd_error(p, volume_header("99999999999 99999999999 99999999999", "uchar", "raw"), kSmallData),
                  "too large");
}

TEST_F(NrrdTest, AttachedDataWithoutBlankLineIsRejected) {
  const std::string p = path("no_blank.nrrd");
  write_file(p, "NRRD0004\ndimension: 3\nsizes: 2 3 4\ntype: uchar\nencoding: raw\n");
  EXPECT_CONTAINS(io_error_of([&] { read_nrrd(p); }), "blank line");
}

TEST_F(NrrdTest, SeveralDetachedDataFilesAreRejected) {
  const std::string p = path("list.nhdr");
  EXPECT_CONTAINS(nrrd_error(p, volume_header("2 3 4", "uchar", "raw", {"data file: LIST"})),
                  "data file 'LIST' not supported");
  EXPECT_CONTAINS(nrrd_error(p, volume_header("2 3 4", "uchar", "raw", {"data file: slice%03d.raw 1 4 1 2"})),
                  "not supported");
}

// ---------------------------------------------------------------- rejected data

TEST_F(NrrdTest, TruncatedRawDataIsRejected) {
  const std::string p = path("short.nrrd");
  const std::string msg = nrrd_error(p, kSmallHeader, Bytes(kSmallData.begin(), kSmallData.end() - 1));
  EXPECT_CONTAINS(msg, p);
  EXPECT_CONTAINS(msg, "data truncated: 23 of 24 bytes");
  write_file(path("short.raw"), "", Bytes(10));
  const std::string at_end = path("at_end.nhdr");
  write_file(at_end, volume_header("2 3 4", "uchar", "raw", {"byte skip: -1", "data file: short.raw"}));
  EXPECT_CONTAINS(io_error_of([&] { read_nrrd(at_end); }), "data truncated: 10 of 24 bytes");
}

TEST_F(NrrdTest, EveryCutOfAnAttachedFileIsRejected) {
  std::string whole = volume_header("2 3 4", "short", "raw", {"endian: big"});
  whole += std::string(48, 'x');
  for (size_t cut = 0; cut < whole.size(); ++cut) {
    SCOPED_TRACE(cut);
    const std::string p = path("cut.nrrd");
    write_file(p, whole.substr(0, cut));
    EXPECT_CONTAINS(io_error_of([&] { read_nrrd(p); }), p);
  }
}

TEST_F(NrrdTest, TruncatedGzipDataIsRejected) {
  const Bytes packed = gzip(read_bytes(kNeghip));
  const std::string p = path("short_gz.nrrd");
  const Bytes half(packed.begin(), packed.begin() + static_cast<std::ptrdiff_t>(packed.size() / 2));
  const std::string msg = nrrd_error(p, volume_header("66 66 66", "uchar", "gzip"), half);
  EXPECT_CONTAINS(msg, p);
  EXPECT_CONTAINS(msg, "data truncated: ");
  EXPECT_CONTAINS(msg, " of 287496 bytes");
  const std::string no_trailer =
      nrrd_error(p, volume_header("66 66 66", "uchar", "gzip"), Bytes(packed.begin(), packed.end() - 8));
  EXPECT_CONTAINS(no_trailer, "data truncated: gzip stream ends without its trailer");
}

TEST_F(NrrdTest, HugeSizesWithLittleDataAreRejectedBeforeAllocating) {
  // 4000^3 nodes would take 256 GB as floats; the file sizes alone show the data cannot be there.
  const std::string p = path("huge.nrrd");
  EXPECT_CONTAINS(nrrd_error(p, volume_header("4000 4000 4000", "uchar", "raw"), kSmallData),
                  "data truncated: 24 of 64000000000 bytes");
  EXPECT_CONTAINS(nrrd_error(p, volume_header("4000 4000 4000", "uchar", "gzip"), gzip(kSmallData)),
                  "data truncated: too little gzip data for 64000000000 bytes");
}

TEST_F(NrrdTest, EveryCutOfAGzipStreamIsRejected) {
  const Bytes packed = gzip(kSmallData);
  for (size_t cut = 0; cut < packed.size(); ++cut) {
    SCOPED_TRACE(cut);
    const std::string p = path("cut_gz.nrrd");
    const std::string msg = nrrd_error(p, volume_header("2 3 4", "uchar", "gzip"),
                                       Bytes(packed.begin(), packed.begin() + static_cast<std::ptrdiff_t>(cut)));
    EXPECT_CONTAINS(msg, "truncated");
  }
}

TEST_F(NrrdTest, GzipDataLongerThanTheHeaderSaysIsRejected) {
  const std::string p = path("long_gz.nrrd");
  Bytes longer = kSmallData;
  longer.push_back(99);
  EXPECT_CONTAINS(nrrd_error(p, volume_header("2 3 4", "uchar", "gzip"), gzip(longer)),
                  "gzip data holds more than the 24 bytes the header describes");
}

TEST_F(NrrdTest, CorruptGzipStreamIsRejected) {
  const Bytes packed = gzip(read_bytes(kNeghip));
  const std::string p = path("corrupt_gz.nrrd");
  Bytes bad_block = packed;
  bad_block[10] = 0xff;  // first deflate block header: final, reserved type 3
  const std::string msg = nrrd_error(p, volume_header("66 66 66", "uchar", "gzip"), bad_block);
  EXPECT_CONTAINS(msg, p);
  EXPECT_CONTAINS(msg, "corrupt gzip data");

  Bytes bad_crc = packed;
  bad_crc[bad_crc.size() - 6] ^= 0x01;  // inside the CRC-32 of the trailer
  EXPECT_CONTAINS(nrrd_error(p, volume_header("66 66 66", "uchar", "gzip"), bad_crc), "corrupt gzip data");

  Bytes not_gzip = packed;
  not_gzip[0] = 0;
  EXPECT_CONTAINS(nrrd_error(p, volume_header("66 66 66", "uchar", "gzip"), not_gzip), "corrupt gzip data");
}

TEST_F(NrrdTest, MissingDetachedDataFileIsRejected) {
  const std::string p = path("orphan.nhdr");
  const std::string msg = nrrd_error(p, volume_header("2 3 4", "uchar", "raw", {"data file: absent.raw"}));
  EXPECT_CONTAINS(msg, p);
  EXPECT_CONTAINS(msg, path("absent.raw") + ": no such file");
}

TEST_F(NrrdTest, NanInDataIsRejectedWithItsCoordinates) {
  std::vector<float> values(3 * 3 * 2, 1.0f);
  values[(0 * 3 + 2) * 3 + 1] = std::numeric_limits<float>::quiet_NaN();  // (x,y,z) = (1,2,0)
  const std::string p = path("nan.nrrd");
  const std::string msg =
      nrrd_error(p, volume_header("3 3 2", "float", "raw", {"endian: big"}), bytes_of(values, std::endian::big));
  EXPECT_CONTAINS(msg, p);
  EXPECT_CONTAINS(msg, "(1,2,0)");
  EXPECT_CONTAINS(msg, "not finite");
  const std::string big = path("big.nrrd");
  EXPECT_CONTAINS(nrrd_error(big, volume_header("1 1 2", "double", "raw", {"endian: little"}),
                             bytes_of(std::vector<double>{1.0, -1e300}, std::endian::little)),
                  "(0,0,1)");
}

TEST_F(NrrdTest, MissingFileAndDirectoryAreRejectedByName) {
  const std::string p = path("absent.nrrd");
  EXPECT_CONTAINS(io_error_of([&] { read_nrrd(p); }), p + ": no such file");
  fs::create_directory(path("dir.nrrd"));
  EXPECT_CONTAINS(io_error_of([&] { read_nrrd(path("dir.nrrd")); }), "is a directory");
}

// ---------------------------------------------------------------- read_volume

TEST_F(NrrdTest, ReadVolumeDispatchesNrrdAndNhdr) {
  const std::string attached = path("small.nrrd");
  write_file(attached, kSmallHeader, kSmallData);
  write_file(path("small.raw"), "", kSmallData);
  const std::string detached = path("SMALL.NHDR");
  write_file(detached, volume_header("2 3 4", "uchar", "raw", {"data file: small.raw", "spacings: 1 2 3"}));
  // --dims and --type describe raw files only; the header wins.
  const Volume a = read_volume({attached, std::array<int64_t, 3>{4, 3, 2}, ScalarType::float32});
  const Volume b = read_volume({detached, {}, {}});
  EXPECT_EQ(a.dims, (std::array<int64_t, 3>{2, 3, 4}));
  EXPECT_EQ(a.values, read_nrrd(attached).values);
  EXPECT_EQ(b.values, a.values);
  EXPECT_EQ(b.spacing, (std::array<double, 3>{1, 2, 3}));
  EXPECT_CONTAINS(io_error_of([&] { read_volume({path("gone.nrrd"), {}, {}}); }), "gone.nrrd: no such file");
}

}  // namespace
}  // namespace isotope
