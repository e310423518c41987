// TIFF stacks (read_tiff_stack, open_tiff_stack): multi-page files and folders of slices, in strips and
// tiles, compressed or not, of every element type isotope reads, give the same values as the raw
// files of the same volumes, whole and box by box; convert streams them into the same store; and
// every bad stack becomes an IoError naming the file and what is wrong.
#include <gtest/gtest.h>
#include <tiffio.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <string>
#include <vector>

#include "io/volume/box_reader.h"
#include "io/volume/raw_reader.h"
#include "io/volume/tiff_reader.h"
#include "io/volume/volume_reader.h"
#include "isotope/convert.h"
#include "isotope/error.h"
#include "isotope/source.h"
#include "tests/support/byte_files.h"
#include "tests/support/io_error_of.h"
#include "tests/support/temp_dir_test.h"

namespace isotope {
namespace {

namespace fs = std::filesystem;
using testing::io_error_of;

const fs::path kData = ISOTOPE_TEST_DATA;
const std::string kNeghip = (kData / "neghip_66x66x66_uint8.raw").string();
const std::string kHydrogen = (kData / "hydrogen_64x64x64_float32.raw").string();

// How a test stack is laid out on disk.
struct Layout {
  uint16_t bits = 8;
  uint16_t format = SAMPLEFORMAT_UINT;
  uint16_t samples = 1;
  uint16_t compression = COMPRESSION_NONE;
  uint32_t tile = 0;            // > 0: tiles of tile x tile, else strips
  uint32_t rows_per_strip = 5;  // a strip boundary inside most boxes
  uint16_t photometric = 0;     // 0: min-is-black, or RGB for 3 samples
  std::string description{};    // the first page's ImageDescription, if any
};

// Writes PAGES (each width*height*samples elements of BITS, as bytes) as one file, one page each.
void write_tiff(const std::string& path, uint32_t width, uint32_t height,
                const std::vector<std::vector<unsigned char>>& pages, const Layout& l) {
  TIFF* tif = TIFFOpen(path.c_str(), "w");
  ASSERT_NE(tif, nullptr);
  const size_t element = l.bits / 8 * l.samples;
  for (const auto& page : pages) {
    TIFFSetField(tif, TIFFTAG_IMAGEWIDTH, width);
    TIFFSetField(tif, TIFFTAG_IMAGELENGTH, height);
    TIFFSetField(tif, TIFFTAG_BITSPERSAMPLE, l.bits);
    TIFFSetField(tif, TIFFTAG_SAMPLEFORMAT, l.format);
    TIFFSetField(tif, TIFFTAG_SAMPLESPERPIXEL, l.samples);
    TIFFSetField(tif, TIFFTAG_PHOTOMETRIC,
                 l.photometric != 0 ? l.photometric
                 : l.samples == 3   ? PHOTOMETRIC_RGB
                                    : PHOTOMETRIC_MINISBLACK);
    if (l.photometric == PHOTOMETRIC_PALETTE) {
      std::vector<uint16_t> map(size_t{1} << l.bits, 0);
      TIFFSetField(tif, TIFFTAG_COLORMAP, map.data(), map.data(), map.data());
    }
    if (!l.description.empty() && &page == &pages.front())
      TIFFSetField(tif, TIFFTAG_IMAGEDESCRIPTION, l.description.c_str());
    TIFFSetField(tif, TIFFTAG_PLANARCONFIG, PLANARCONFIG_CONTIG);
    TIFFSetField(tif, TIFFTAG_COMPRESSION, l.compression);
    if (pages.size() > 1) TIFFSetField(tif, TIFFTAG_SUBFILETYPE, FILETYPE_PAGE);
    if (l.tile > 0) {
      TIFFSetField(tif, TIFFTAG_TILEWIDTH, l.tile);
      TIFFSetField(tif, TIFFTAG_TILELENGTH, l.tile);
      std::vector<unsigned char> tile(size_t{l.tile} * l.tile * element, 0);
      for (uint32_t ty = 0; ty < height; ty += l.tile)
        for (uint32_t tx = 0; tx < width; tx += l.tile) {
          std::fill(tile.begin(), tile.end(), 0);
          for (uint32_t y = ty; y < std::min(height, ty + l.tile); ++y)
            for (uint32_t x = tx; x < std::min(width, tx + l.tile); ++x)
              std::memcpy(&tile[((y - ty) * l.tile + (x - tx)) * element], &page[(size_t{y} * width + x) * element],
                          element);
          ASSERT_GE(TIFFWriteTile(tif, tile.data(), tx, ty, 0, 0), 0);
        }
    } else {
      TIFFSetField(tif, TIFFTAG_ROWSPERSTRIP, l.rows_per_strip);
      for (uint32_t y = 0; y < height; ++y)
        ASSERT_EQ(TIFFWriteScanline(tif, const_cast<unsigned char*>(&page[size_t{y} * width * element]), y, 0), 1);
    }
    ASSERT_EQ(TIFFWriteDirectory(tif), 1);
  }
  TIFFClose(tif);
}

// A volume's values in its raw file's element type, slice by slice.
std::vector<std::vector<unsigned char>> slices_of(const std::string& raw_path) {
  const RawLayout layout = *parse_raw_name(raw_path);
  const testing::Bytes bytes = testing::read_bytes(raw_path);
  const size_t slice = static_cast<size_t>(layout.dims[0] * layout.dims[1] * scalar_type_size(layout.type));
  std::vector<std::vector<unsigned char>> out;
  for (int64_t z = 0; z < layout.dims[2]; ++z)
    out.emplace_back(bytes.begin() + static_cast<ptrdiff_t>(z * slice),
                     bytes.begin() + static_cast<ptrdiff_t>((z + 1) * slice));
  return out;
}

VolumeSpec spec(const std::string& path) {
  VolumeSpec s;
  s.path = path;
  return s;
}

Volume raw(const std::string& path) { return read_raw(path, *parse_raw_name(path)); }

void expect_same_values(const Volume& got, const Volume& want) {
  ASSERT_EQ(got.dims, want.dims);
  ASSERT_EQ(got.values.size(), want.values.size());
  EXPECT_EQ(std::memcmp(got.values.data(), want.values.data(), want.values.size() * sizeof(float)), 0);
}

// Boxes that cross strip, tile and slice boundaries, read concurrently with the whole.
void expect_same_boxes(const BoxReader& reader, const Volume& want) {
  const auto& d = want.dims;
  for (const auto& [lo, size] : std::vector<std::pair<std::array<int64_t, 3>, std::array<int64_t, 3>>>{
           {{0, 0, 0}, {d[0], d[1], d[2]}}, {{3, 4, 5}, {17, 13, 9}}, {{d[0] - 7, d[1] - 11, d[2] - 2}, {7, 11, 2}}}) {
    std::vector<float> box(static_cast<size_t>(size[0] * size[1] * size[2]));
    reader.read_box(lo, size, box.data());
    size_t i = 0;
    for (int64_t z = 0; z < size[2]; ++z)
      for (int64_t y = 0; y < size[1]; ++y)
        for (int64_t x = 0; x < size[0]; ++x, ++i)
          ASSERT_EQ(box[i], want.at(lo[0] + x, lo[1] + y, lo[2] + z)) << x << "," << y << "," << z;
  }
}

using TiffStack = testing::TempDirTest;

TEST_F(TiffStack, MultiPageLzwStripsEqualTheRawVolume) {
  const Volume want = raw(kNeghip);
  write_tiff(path("neghip.tif"), 66, 66, slices_of(kNeghip), {.compression = COMPRESSION_LZW});
  expect_same_values(read_volume(spec(path("neghip.tif"))), want);
  const auto reader = open_box_reader(spec(path("neghip.tif")), path(""));
  EXPECT_EQ(reader->info().type, "uint8");
  EXPECT_TRUE(reader->info().is_integer);
  expect_same_boxes(*reader, want);
}

TEST_F(TiffStack, FolderOfTiledDeflateFloatSlicesInNaturalOrderEqualsTheRawVolume) {
  const Volume want = raw(kHydrogen);
  fs::create_directory(path("slices"));
  const auto slices = slices_of(kHydrogen);
  // Unpadded numbers: slice_10 must come after slice_9, not after slice_1.
  for (size_t z = 0; z < slices.size(); ++z)
    write_tiff(path("slices/slice_" + std::to_string(z) + ".TIF"), 64, 64, {slices[z]},
               {.bits = 32, .format = SAMPLEFORMAT_IEEEFP, .compression = COMPRESSION_ADOBE_DEFLATE, .tile = 16});
  testing::write_file(path("slices/notes.txt"), "not a slice");
  expect_same_values(read_volume(spec(path("slices"))), want);
  const auto reader = open_box_reader(spec(path("slices")), path(""));
  EXPECT_EQ(reader->info().type, "float32");
  expect_same_boxes(*reader, want);
}

// A stack opened for extraction (a Source) is streamed at eps 0: the mesh of its values.
TEST_F(TiffStack, AStackIsStreamedAtEpsZeroToTheMeshOfItsValues) {
  write_tiff(path("neghip.tif"), 66, 66, slices_of(kNeghip), {.compression = COMPRESSION_LZW});
  ExtractOptions o;
  o.iso = 128.5f;
  const Mesh want = extract(raw(kNeghip), o);
  ASSERT_GT(want.triangles.size(), 0u);
  const Source stack = open_volume(spec(path("neghip.tif")));
  const Mesh got = stack.extract(o);
  EXPECT_TRUE(got.positions == want.positions && got.triangles == want.triangles);
  EXPECT_FALSE(stack.info().values_in_memory);
}

TEST_F(TiffStack, EveryElementTypeIsReadAsItsValues) {
  const uint32_t w = 5, h = 4;
  const auto pages_of = [&](auto sample) {
    using T = decltype(sample);
    std::vector<std::vector<unsigned char>> pages;
    for (int z = 0; z < 3; ++z) {
      std::vector<unsigned char> page(w * h * sizeof(T));
      for (uint32_t i = 0; i < w * h; ++i) {
        const T v = static_cast<T>(std::is_signed_v<T> ? int(i) * 37 - 300 * z - 100 : int(i) * 3 + 50 * z);
        std::memcpy(&page[i * sizeof(T)], &v, sizeof(T));
      }
      pages.push_back(page);
    }
    return pages;
  };
  const auto check = [&](const std::string& name, auto sample, Layout layout, const std::string& type) {
    using T = decltype(sample);
    write_tiff(path(name), w, h, pages_of(sample), layout);
    const Volume v = read_volume(spec(path(name)));
    EXPECT_EQ(v.dims, (std::array<int64_t, 3>{w, h, 3}));
    EXPECT_EQ(open_box_reader(spec(path(name)), path(""))->info().type, type);
    for (int z = 0; z < 3; ++z)
      for (uint32_t i = 0; i < w * h; ++i)
        EXPECT_EQ(v.values[z * w * h + i],
                  static_cast<float>(
                      static_cast<T>(std::is_signed_v<T> ? int(i) * 37 - 300 * z - 100 : int(i) * 3 + 50 * z)));
  };
  check("u8.tif", uint8_t{}, {.bits = 8}, "uint8");
  check("u16.tif", uint16_t{}, {.bits = 16, .compression = COMPRESSION_PACKBITS}, "uint16");
  check("i16.tif", int16_t{}, {.bits = 16, .format = SAMPLEFORMAT_INT}, "int16");
  check("f32.tif", float{}, {.bits = 32, .format = SAMPLEFORMAT_IEEEFP, .tile = 16}, "float32");
  check("f64.tif", double{}, {.bits = 64, .format = SAMPLEFORMAT_IEEEFP, .compression = COMPRESSION_LZW}, "float64");
}

// Integers of one or two bytes are read as the pages store them, in this machine's byte order,
// for the one-shot march: any box across strips, tiles and pages, byte for byte; floats are not.
TEST_F(TiffStack, SmallIntegersAreReadAsStoredAcrossStripsTilesAndPages) {
  const uint32_t w = 37, h = 29;
  const uint32_t pages = 6;
  const auto check = [&](const std::string& name, auto sample, Layout layout, ScalarType type) {
    using T = decltype(sample);
    SCOPED_TRACE(name);
    std::vector<T> values(size_t{w} * h * pages);
    for (size_t i = 0; i < values.size(); ++i)
      values[i] = static_cast<T>(std::is_signed_v<T> ? int(i) * -97 + 300 : int(i) * 211 + 7);
    std::vector<std::vector<unsigned char>> slices;
    for (size_t z = 0; z < pages; ++z) {
      const auto* first = reinterpret_cast<const unsigned char*>(values.data() + z * w * h);
      slices.emplace_back(first, first + size_t{w} * h * sizeof(T));
    }
    write_tiff(path(name), w, h, slices, layout);
    const auto reader = open_box_reader(spec(path(name)), path(""));
    ASSERT_EQ(reader->stored_type(), type);
    for (const auto& [lo, size] : std::vector<std::pair<std::array<int64_t, 3>, std::array<int64_t, 3>>>{
             {{0, 0, 0}, {w, h, pages}}, {{3, 4, 1}, {17, 13, 4}}, {{w - 7, h - 11, 4}, {7, 11, 2}}}) {
      std::vector<T> box(static_cast<size_t>(size[0] * size[1] * size[2]));
      reader->read_box_stored(lo, size, reinterpret_cast<unsigned char*>(box.data()));
      size_t i = 0;
      for (int64_t z = 0; z < size[2]; ++z)
        for (int64_t y = 0; y < size[1]; ++y)
          for (int64_t x = 0; x < size[0]; ++x, ++i)
            ASSERT_EQ(box[i], values[static_cast<size_t>(((lo[2] + z) * h + lo[1] + y) * w + lo[0] + x)])
                << x << "," << y << "," << z;
    }
  };
  check("u8.tif", uint8_t{}, {.bits = 8, .compression = COMPRESSION_LZW}, ScalarType::uint8);
  check("u16.tif", uint16_t{}, {.bits = 16, .compression = COMPRESSION_PACKBITS, .tile = 16}, ScalarType::uint16);
  check("i16.tif", int16_t{}, {.bits = 16, .format = SAMPLEFORMAT_INT}, ScalarType::int16);
  write_tiff(path("f32.tif"), w, h, std::vector<std::vector<unsigned char>>(2, std::vector<unsigned char>(w * h * 4)),
             {.bits = 32, .format = SAMPLEFORMAT_IEEEFP});
  EXPECT_EQ(open_box_reader(spec(path("f32.tif")), path(""))->stored_type(), std::nullopt);
}

// convert reads the stack box by box (streamed, as raw input is); the store is the raw volume's.
TEST_F(TiffStack, ConvertGivesTheStoreOfTheRawVolume) {
  write_tiff(path("neghip.tif"), 66, 66, slices_of(kNeghip), {.compression = COMPRESSION_LZW, .tile = 16});
  convert(spec(path("neghip.tif")), path("from_tiff.isotope"));
  convert(spec(kNeghip), path("from_raw.isotope"));
  EXPECT_EQ(testing::read_bytes(path("from_tiff.isotope")), testing::read_bytes(path("from_raw.isotope")));
}

TEST_F(TiffStack, BadStacksAreRefusedByName) {
  const std::vector<unsigned char> gray(8 * 8, 7), rgb(8 * 8 * 3, 7), wide(8 * 8 * 4, 7);
  write_tiff(path("rgb.tif"), 8, 8, {rgb, rgb}, {.samples = 3});
  EXPECT_CONTAINS(io_error_of([&] { read_volume(spec(path("rgb.tif"))); }),
                  "rgb.tif: 3 samples per pixel; isotope reads one channel per pixel");
  write_tiff(path("int32.tif"), 8, 8, {wide, wide}, {.bits = 32, .format = SAMPLEFORMAT_INT});
  EXPECT_CONTAINS(io_error_of([&] { read_volume(spec(path("int32.tif"))); }),
                  "int32.tif: 32-bit signed integer samples");
  // Pages of different sizes in one file.
  {
    TIFF* tif = TIFFOpen(path("mixed.tif").c_str(), "w");
    for (uint32_t w : {8u, 6u}) {
      TIFFSetField(tif, TIFFTAG_IMAGEWIDTH, w);
      TIFFSetField(tif, TIFFTAG_IMAGELENGTH, 8u);
      TIFFSetField(tif, TIFFTAG_BITSPERSAMPLE, 8);
      TIFFSetField(tif, TIFFTAG_SAMPLESPERPIXEL, 1);
      TIFFSetField(tif, TIFFTAG_ROWSPERSTRIP, 8u);
      TIFFWriteEncodedStrip(tif, 0, const_cast<unsigned char*>(gray.data()), w * 8);
      TIFFWriteDirectory(tif);
    }
    TIFFClose(tif);
  }
  EXPECT_CONTAINS(io_error_of([&] { read_volume(spec(path("mixed.tif"))); }),
                  "mixed.tif: page 1 is 6x8 uint8, where page 0 is 8x8 uint8");
  // A folder whose slices differ, an empty folder, a file that is no TIFF.
  fs::create_directory(path("slices"));
  write_tiff(path("slices/a1.tif"), 8, 8, {gray}, {});
  write_tiff(path("slices/a2.tif"), 8, 8, {wide}, {.bits = 32, .format = SAMPLEFORMAT_IEEEFP});
  EXPECT_CONTAINS(io_error_of([&] { read_volume(spec(path("slices"))); }),
                  "a2.tif: a slice of 8x8 float32, where " + path("slices/a1.tif") + " is 8x8 uint8");
  fs::create_directory(path("empty"));
  EXPECT_CONTAINS(io_error_of([&] { read_volume(spec(path("empty"))); }),
                  "empty: is a directory without .tif or .tiff files");
  testing::write_file(path("text.tif"), "this is not a TIFF file at all");
  EXPECT_CONTAINS(io_error_of([&] { read_volume(spec(path("text.tif"))); }), "text.tif: not a readable TIFF file");
  EXPECT_CONTAINS(io_error_of([&] { read_volume(spec(path("missing.tif"))); }), "missing.tif: no such file");
}

TEST_F(TiffStack, TruncatedAndNonFiniteDataAreIoErrors) {
  write_tiff(path("neghip.tif"), 66, 66, slices_of(kNeghip), {.compression = COMPRESSION_LZW});
  // The directories stay (libtiff writes each page's after its data), the last strips are cut.
  testing::Bytes bytes = testing::read_bytes(path("neghip.tif"));
  {
    TIFF* tif = TIFFOpen(path("neghip.tif").c_str(), "r");
    TIFFSetDirectory(tif, 65);
    uint64_t* offsets = nullptr;
    TIFFGetField(tif, TIFFTAG_STRIPOFFSETS, &offsets);
    const uint64_t cut_from = offsets[0] + 10;
    TIFFClose(tif);
    // Zero the data of the last page's strips: LZW refuses the codes.
    std::fill(bytes.begin() + static_cast<ptrdiff_t>(cut_from), bytes.begin() + static_cast<ptrdiff_t>(cut_from + 200),
              0xFF);
  }
  testing::write_file(path("damaged.tif"), "", bytes);
  const std::string message = io_error_of([&] { read_volume(spec(path("damaged.tif"))); });
  EXPECT_CONTAINS(message, "damaged.tif: page 65: strip");
  EXPECT_CONTAINS(message, "cannot be read");

  std::vector<unsigned char> page(4 * 4 * 4, 0);
  const float nan = std::numeric_limits<float>::quiet_NaN();
  std::memcpy(&page[(2 * 4 + 1) * 4], &nan, 4);
  write_tiff(path("nan.tif"), 4, 4, {std::vector<unsigned char>(64, 0), page},
             {.bits = 32, .format = SAMPLEFORMAT_IEEEFP});
  EXPECT_CONTAINS(io_error_of([&] { read_volume(spec(path("nan.tif"))); }), "nan.tif");
  EXPECT_CONTAINS(io_error_of([&] { read_volume(spec(path("nan.tif"))); }), "at (x,y,z) = (1,2,1) is not finite");
  // Unchecked, the NaN is read as it is.
  const auto reader = open_box_reader(spec(path("nan.tif")), "");
  std::vector<float> values(32, 7.0f);
  reader->read_box_unchecked({0, 0, 0}, {4, 4, 2}, values.data());
  EXPECT_TRUE(std::isnan(values[16 + 2 * 4 + 1]));
  EXPECT_EQ(std::count_if(values.begin(), values.end(), [](float v) { return v == 0.0f; }), 31);
}

// The value of TAG in every directory of a classic little-endian TIFF, set to VALUE (SHORT or LONG),
// or the tag's number changed to VALUE when RENUMBER: a file's header made to lie.
void patch_tag(testing::Bytes& b, uint16_t tag, uint32_t value, bool renumber = false) {
  auto u16 = [&](size_t at) { return static_cast<uint16_t>(b[at] | b[at + 1] << 8); };
  auto u32 = [&](size_t at) { return static_cast<uint32_t>(u16(at) | u16(at + 2) << 16); };
  for (uint32_t ifd = u32(4); ifd != 0; ifd = u32(ifd + 2 + 12 * size_t{u16(ifd)})) {
    for (size_t e = ifd + 2; e < ifd + 2 + 12 * size_t{u16(ifd)}; e += 12) {
      if (u16(e) != tag) continue;
      if (renumber) {
        b[e] = static_cast<uint8_t>(value), b[e + 1] = static_cast<uint8_t>(value >> 8);
      } else {
        for (int k = 0; k < (u16(e + 2) == 3 ? 2 : 4); ++k) b[e + 8 + k] = static_cast<uint8_t>(value >> (8 * k));
      }
    }
  }
}

// Stacks whose files are not what they claim, or not one channel's slices in order, are refused by
// name rather than read as something else: libtiff's warnings that mean it would guess at the data
// (a strip table that disagrees with RowsPerStrip: it read the strips from offset 0, the header,
// giving 0..155 for values 100..227), palette images (indices, not values), hyperstacks whose
// pages interleave channels or time points, links in a slice folder that lead nowhere (skipped or
// refused by the directory's order before), and a single page (no cells between slices).
TEST_F(TiffStack, StacksThatAreNotOneChannelsSlicesAsTheyClaimAreRefusedByName) {
  std::vector<unsigned char> page(8 * 16);
  for (size_t i = 0; i < page.size(); ++i) page[i] = static_cast<unsigned char>(100 + i);
  write_tiff(path("good.tif"), 8, 16, {page, page}, {.rows_per_strip = 16});
  testing::Bytes bytes = testing::read_bytes(path("good.tif"));
  patch_tag(bytes, TIFFTAG_ROWSPERSTRIP, 7);  // 3 strips, where the table holds 1
  testing::write_file(path("lying.tif"), "", bytes);
  for (const auto& read : {std::function<void()>([&] { read_volume(spec(path("lying.tif"))); }),
                           std::function<void()>([&] { open_box_reader(spec(path("lying.tif")), path("")); })}) {
    const std::string message = io_error_of(read);
    EXPECT_CONTAINS(message, "lying.tif: page 0: its directory does not describe its data consistently");
    EXPECT_CONTAINS(message, "Incorrect count for \"StripOffsets\"");
  }
  // Warnings about other tags leave the values as they are: a private tag libtiff does not know
  // (as ImageJ's and microscopes' are), out of order.
  bytes = testing::read_bytes(path("good.tif"));
  patch_tag(bytes, TIFFTAG_SUBFILETYPE, 65000, true);
  testing::write_file(path("private.tif"), "", bytes);
  const Volume v = read_volume(spec(path("private.tif")));
  EXPECT_EQ(v.values.front(), 100.0f);
  EXPECT_EQ(v.values.back(), 227.0f);

  write_tiff(path("palette.tif"), 8, 16, {page, page}, {.photometric = PHOTOMETRIC_PALETTE});
  EXPECT_CONTAINS(io_error_of([&] { read_volume(spec(path("palette.tif"))); }),
                  "palette.tif: a palette (indexed colour) image");
  const std::vector<std::vector<unsigned char>> four = {page, page, page, page};
  write_tiff(path("channels.tif"), 8, 16, four,
             {.description = "ImageJ=1.54f\nimages=4\nchannels=2\nslices=2\nhyperstack=true\nmode=composite\n"});
  EXPECT_CONTAINS(io_error_of([&] { read_volume(spec(path("channels.tif"))); }),
                  "channels.tif: a hyperstack of 2 channels, whose pages interleave them");
  write_tiff(path("frames.tif"), 8, 16, four, {.description = "ImageJ=1.54f\nimages=4\nslices=2\nframes=2\n"});
  EXPECT_CONTAINS(io_error_of([&] { read_volume(spec(path("frames.tif"))); }),
                  "frames.tif: a hyperstack of 2 time points of 2 slices each");
  write_tiff(path("ome.tif"), 8, 16, four,
             {.description = "<?xml version=\"1.0\"?><OME><Image><Pixels SizeC=\"2\" SizeZ=\"2\" SizeT=\"1\"/>"
                             "</Image></OME>"});
  EXPECT_CONTAINS(io_error_of([&] { read_volume(spec(path("ome.tif"))); }), "ome.tif: a hyperstack of 2 channels");
  // Bio-Formats writes PhysicalSizeZ before SizeZ: it is not the count of slices.
  write_tiff(path("ome5d.tif"), 8, 16, four,
             {.description = "<OME><Image><Pixels PhysicalSizeZ=\"0.3\" SizeC=\"1\" SizeT=\"2\" SizeZ=\"2\"/>"
                             "</Image></OME>"});
  EXPECT_CONTAINS(io_error_of([&] { read_volume(spec(path("ome5d.tif"))); }),
                  "ome5d.tif: a hyperstack of 2 time points of 2 slices each");
  write_tiff(path("ome-time.tif"), 8, 16, four,
             {.description = "<OME><Image><Pixels PhysicalSizeZ=\"2.5\" SizeC=\"1\" SizeT=\"4\" SizeZ=\"1\"/>"
                             "</Image></OME>"});
  EXPECT_EQ(read_volume(spec(path("ome-time.tif"))).dims, (std::array<int64_t, 3>{8, 16, 4}));
  write_tiff(path("slices.tif"), 8, 16, four, {.description = "ImageJ=1.54f\nimages=4\nslices=4\n"});
  EXPECT_EQ(read_volume(spec(path("slices.tif"))).dims, (std::array<int64_t, 3>{8, 16, 4}));

  // A link that leads nowhere, between two slices: named, whatever the directory's order.
  fs::create_directory(path("linked"));
  write_tiff(path("linked/s1.tif"), 8, 16, {page}, {});
  write_tiff(path("linked/s3.tif"), 8, 16, {page}, {});
  fs::create_symlink("gone.tif", path("linked/s2.tif"));
  EXPECT_CONTAINS(io_error_of([&] { read_volume(spec(path("linked"))); }),
                  "linked/s2.tif: a symbolic link that leads nowhere");
  fs::remove(path("linked/s2.tif"));
  fs::create_symlink("s4.tif", path("linked/s4.tif"));  // a loop
  EXPECT_CONTAINS(io_error_of([&] { read_volume(spec(path("linked"))); }),
                  "linked/s4.tif: a symbolic link that leads nowhere");
  fs::remove(path("linked/s4.tif"));
  fs::create_directory(path("linked/s5.tif"));
  EXPECT_CONTAINS(io_error_of([&] { read_volume(spec(path("linked"))); }),
                  "linked/s5.tif: a directory named like a slice");

  write_tiff(path("one.tif"), 8, 16, {page}, {});
  for (const auto& read : {std::function<void()>([&] { read_volume(spec(path("one.tif"))); }),
                           std::function<void()>([&] { open_box_reader(spec(path("one.tif")), path("")); })})
    EXPECT_CONTAINS(io_error_of(read),
                    "one.tif: volume dimensions 8x16x1 (x by y by z): every axis needs 2 .. 524289 nodes");
}

}  // namespace
}  // namespace isotope
