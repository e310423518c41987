#include "io/volume/tiff_reader.h"

#include <tiffio.h>

#include <algorithm>
#include <bit>
#include <cctype>
#include <cstdarg>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <optional>
#include <stdexcept>
#include <system_error>
#include <vector>

#include "engine/core/huge_blocks.h"
#include "io/file/extension.h"
#include "io/file/input_file.h"
#include "io/volume/raw_reader.h"
#include "isotope/error.h"

namespace isotope {
namespace {

namespace fs = std::filesystem;

// What libtiff may allocate at once for one strip, tile or directory: a header that lies about
// a strip's size is refused instead of being believed (docs/RELIABILITY.md).
constexpr tmsize_t kMaxTiffAllocation = tmsize_t{256} << 20;

bool has_tiff_extension(const fs::path& path) {
  const std::string ext = lowercase_extension(path);
  return ext == ".tif" || ext == ".tiff";
}

// "slice_2.tif" before "slice_10.tif": runs of digits compare as numbers, the rest as bytes.
bool natural_less(const std::string& a, const std::string& b) {
  size_t i = 0, j = 0;
  while (i < a.size() && j < b.size()) {
    if (std::isdigit(static_cast<unsigned char>(a[i])) && std::isdigit(static_cast<unsigned char>(b[j]))) {
      size_t ie = i, je = j;
      while (ie < a.size() && std::isdigit(static_cast<unsigned char>(a[ie]))) ++ie;
      while (je < b.size() && std::isdigit(static_cast<unsigned char>(b[je]))) ++je;
      const std::string_view da = std::string_view(a).substr(i, ie - i), db = std::string_view(b).substr(j, je - j);
      const size_t za = da.find_first_not_of('0'), zb = db.find_first_not_of('0');
      const std::string_view na = za == std::string_view::npos ? "" : da.substr(za);
      const std::string_view nb = zb == std::string_view::npos ? "" : db.substr(zb);
      if (na.size() != nb.size()) return na.size() < nb.size();
      if (na != nb) return na < nb;
      i = ie, j = je;
    } else {
      if (a[i] != b[j]) return static_cast<unsigned char>(a[i]) < static_cast<unsigned char>(b[j]);
      ++i, ++j;
    }
  }
  if (a.size() - i != b.size() - j) return a.size() - i < b.size() - j;
  return a < b;  // equal as numbers ("1" and "01"): any fixed order
}

// libtiff reports through handlers; these keep its first error of a handle for our message (the
// first is the cause, later ones its consequences), and its first warning that means the values
// would not be the file's own (warning_affects_data), and let it print nothing.
struct TiffErrors {
  std::string first;
  std::string data_warning;
};

std::string libtiff_text(const char* module, const char* format, va_list args) {
  char text[512];
  std::vsnprintf(text, sizeof text, format, args);
  return std::string(module ? module : "libtiff") + ": " + text;
}

int keep_error(TIFF*, void* user, const char* module, const char* format, va_list args) {
  auto* errors = static_cast<TiffErrors*>(user);
  if (errors->first.empty()) errors->first = libtiff_text(module, format, args);
  return 1;  // handled
}

// Whether a libtiff warning means that what it reads would not be the values the file holds: it
// ignored, trimmed or guessed a field that lays the data out ("Incorrect count for "StripOffsets";
// tag ignored": the strips then read from offset 0; "calculating from imagelength"), or assumed
// what the file does not say ("BitsPerSample tag is missing, assuming 8 bits per sample").
// Warnings about other tags (a date, a resolution, a private tag of ImageJ or a microscope) and
// about the file's age or tidiness ("Old-style LZW codes", which libtiff decodes as they are)
// leave the values as they are.
bool warning_affects_data(const std::string& text) {
  for (const char* guess : {"calculating from", "assuming", "assumed"})
    if (text.find(guess) != std::string::npos) return true;
  const size_t open = text.find('"'), close = open == std::string::npos ? open : text.find('"', open + 1);
  if (close == std::string::npos) return false;  // names no tag
  static const std::vector<std::string> kLayout = {
      "ImageWidth",          "ImageLength",     "BitsPerSample",   "Compression",  "PhotometricInterpretation",
      "FillOrder",           "StripOffsets",    "SamplesPerPixel", "RowsPerStrip", "StripByteCounts",
      "PlanarConfiguration", "Predictor",       "ColorMap",        "TileWidth",    "TileLength",
      "TileOffsets",         "TileByteCounts",  "TileDepth",       "ExtraSamples", "SampleFormat",
      "JPEGTables",          "YCbCrSubsampling"};
  const std::string tag = text.substr(open + 1, close - open - 1);
  return std::find(kLayout.begin(), kLayout.end(), tag) != kLayout.end();
}

int keep_data_warning(TIFF*, void* user, const char* module, const char* format, va_list args) {
  auto* errors = static_cast<TiffErrors*>(user);
  if (errors->data_warning.empty()) {
    std::string text = libtiff_text(module, format, args);
    if (warning_affects_data(text)) errors->data_warning = std::move(text);
  }
  return 1;
}

class TiffFile {
 public:
  TiffFile(const std::string& path, const std::string& where) : where_(where) {
    require_regular_file(path, where, "a TIFF file");
    TIFFOpenOptions* options = TIFFOpenOptionsAlloc();
    TIFFOpenOptionsSetMaxSingleMemAlloc(options, kMaxTiffAllocation);
    TIFFOpenOptionsSetErrorHandlerExtR(options, keep_error, errors_.get());
    TIFFOpenOptionsSetWarningHandlerExtR(options, keep_data_warning, errors_.get());
    // "m": read, never map: a file truncated while mapped would end the process with SIGBUS.
    tif_ = TIFFOpenExt(path.c_str(), "rm", options);
    TIFFOpenOptionsFree(options);
    if (!tif_) fail("not a readable TIFF file");
    std::error_code ec;
    const uintmax_t size = fs::file_size(path, ec);
    size_ = ec ? 0 : size;  // unknown: every page's data is then refused as missing
  }
  ~TiffFile() {
    if (tif_) TIFFClose(tif_);
  }
  TiffFile(const TiffFile&) = delete;
  TiffFile& operator=(const TiffFile&) = delete;

  TIFF* get() const { return tif_; }
  [[noreturn]] void fail(const std::string& what) const {
    throw IoError(where_ + ": " + what + (errors_->first.empty() ? "" : " (" + errors_->first + ")"));
  }
  bool had_error() const { return !errors_->first.empty(); }
  // Refuses a file of which libtiff would read values that are not the file's own (a field it
  // ignored or guessed): another reader may read such a file differently, and isotope does not
  // guess.
  void refuse_guessed_data(const std::string& page) const {
    if (!errors_->data_warning.empty())
      throw IoError(where_ + ": " + page + ": its directory does not describe its data consistently (" +
                    errors_->data_warning + "); isotope does not read values that libtiff would guess");
  }
  uint64_t size() const { return size_; }

 private:
  std::unique_ptr<TiffErrors> errors_ = std::make_unique<TiffErrors>();  // an address libtiff keeps
  std::string where_;
  TIFF* tif_ = nullptr;
  uint64_t size_ = 0;
};

struct PageFormat {
  uint32_t width = 0, height = 0;
  ScalarType type = ScalarType::uint8;
  bool operator==(const PageFormat&) const = default;
};

std::string describe(const PageFormat& f) {
  return std::to_string(f.width) + "x" + std::to_string(f.height) + " " + scalar_type_name(f.type);
}

// The current page's size and element type; throws unless it is one channel of a type isotope reads.
PageFormat page_format(const TiffFile& file) {
  TIFF* tif = file.get();
  PageFormat f;
  uint16_t samples = 1, bits = 1, format = SAMPLEFORMAT_UINT;
  if (!TIFFGetField(tif, TIFFTAG_IMAGEWIDTH, &f.width) || !TIFFGetField(tif, TIFFTAG_IMAGELENGTH, &f.height) ||
      f.width == 0 || f.height == 0)
    file.fail("a page without a width and height");
  TIFFGetFieldDefaulted(tif, TIFFTAG_SAMPLESPERPIXEL, &samples);
  TIFFGetFieldDefaulted(tif, TIFFTAG_BITSPERSAMPLE, &bits);
  TIFFGetFieldDefaulted(tif, TIFFTAG_SAMPLEFORMAT, &format);
  if (samples != 1)
    file.fail(std::to_string(samples) + " samples per pixel; isotope reads one channel per pixel (a grayscale stack)");
  uint16_t photometric = PHOTOMETRIC_MINISBLACK;
  if (TIFFGetField(tif, TIFFTAG_PHOTOMETRIC, &photometric) && photometric == PHOTOMETRIC_PALETTE)
    file.fail(
        "a palette (indexed colour) image: its values are indices into a colour map, not measurements; "
        "isotope reads grayscale stacks");
  const std::optional<ScalarType> type = format == SAMPLEFORMAT_UINT && bits == 8      ? ScalarType::uint8
                                         : format == SAMPLEFORMAT_UINT && bits == 16   ? ScalarType::uint16
                                         : format == SAMPLEFORMAT_INT && bits == 16    ? ScalarType::int16
                                         : format == SAMPLEFORMAT_IEEEFP && bits == 32 ? ScalarType::float32
                                         : format == SAMPLEFORMAT_IEEEFP && bits == 64
                                             ? std::optional(ScalarType::float64)
                                             : std::nullopt;
  if (!type) {
    const char* kind = format == SAMPLEFORMAT_UINT     ? "unsigned integer"
                       : format == SAMPLEFORMAT_INT    ? "signed integer"
                       : format == SAMPLEFORMAT_IEEEFP ? "floating-point"
                                                       : "other";
    file.fail(std::to_string(bits) + "-bit " + kind +
              " samples; isotope reads uint8, uint16, int16, float32 and float64 TIFF");
  }
  f.type = *type;
  return f;
}

// How many decoded bytes one stored byte can at most become under a compression: a page whose
// header claims more values than its strips could hold is refused before anything is allocated
// (a 1 KB file cannot make isotope allocate gigabytes). Generous bounds: deflate reaches about
// 1032:1, LZW's 12-bit codes about 2730:1, PackBits 64:1; other codecs are allowed 4096:1.
uint64_t max_expansion(uint16_t compression) {
  switch (compression) {
    case COMPRESSION_NONE: return 1;
    case COMPRESSION_PACKBITS: return 64;
    case COMPRESSION_ADOBE_DEFLATE:
    case COMPRESSION_DEFLATE: return 1100;
    default: return 4096;
  }
}

// The current page's strips or tiles hold enough bytes for the values its header claims; returns
// those values' bytes.
uint64_t check_page_data(const TiffFile& file, const PageFormat& f, const std::string& page) {
  TIFF* tif = file.get();
  uint16_t compression = COMPRESSION_NONE;
  TIFFGetFieldDefaulted(tif, TIFFTAG_COMPRESSION, &compression);
  const uint32_t pieces = TIFFIsTiled(tif) ? TIFFNumberOfTiles(tif) : TIFFNumberOfStrips(tif);
  if (pieces > file.size()) file.fail(page + ": more strips than the file has bytes (a damaged header)");
  uint64_t stored = 0;  // the bytes of its strips that lie inside the file
  for (uint32_t i = 0; i < pieces; ++i) {
    const uint64_t at = TIFFGetStrileOffset(tif, i), count = TIFFGetStrileByteCount(tif, i);
    if (at < file.size()) stored += std::min(count, file.size() - at);
  }
  const uint64_t decoded = uint64_t{f.width} * f.height * static_cast<uint64_t>(scalar_type_size(f.type));
  if (file.had_error()) file.fail(page + ": a damaged directory");
  stored = std::min(stored, file.size());  // strips may overlap: a page holds at most the file
  if (decoded / max_expansion(compression) > stored)
    file.fail(page + ": its strips hold " + std::to_string(stored) + " bytes, too few for " + describe(f) +
              " values (a damaged or lying header)");
  file.refuse_guessed_data(page);
  return decoded;
}

struct Stack {
  std::string where;               // the path the user named
  std::vector<std::string> files;  // one per slice; a multi-page file once
  bool multipage = false;
  std::vector<toff_t> directories;  // a multi-page file: where each page's directory is, to go
                                    // straight to it (TIFFSetDirectory walks the chain from page 0)
  PageFormat format;
  int64_t pages = 0;
};

std::vector<std::string> folder_slices(const std::string& dir) {
  std::vector<std::string> names;
  std::error_code ec;
  for (fs::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
    const std::string name = it->path().filename().string();
    // Hidden files (macOS's "._slice.tif" among them) are not slices.
    if (!name.empty() && name[0] != '.' && has_tiff_extension(it->path())) names.push_back(name);
  }
  if (ec) throw IoError(dir + ": cannot list the folder: " + ec.message());
  if (names.empty())
    throw IoError(
        dir + ": is a directory without .tif or .tiff files (a folder is read as a TIFF stack, one file per slice)");
  std::sort(names.begin(), names.end(), natural_less);
  // Every slice a regular file (links followed), checked in slice order: whatever order the
  // directory lists them in, the same entry is named.
  for (std::string& n : names) {
    const fs::path p = fs::path(dir) / n;
    std::error_code status_error;
    const fs::file_status st = fs::status(p, status_error);
    if (!fs::exists(st)) {
      std::error_code link_error;
      if (fs::is_symlink(fs::symlink_status(p, link_error)))
        throw IoError(p.string() +
                      ": a symbolic link that leads nowhere (dangling, or a loop); every .tif in a "
                      "slice folder is a slice, so the stack would lack one");
      throw IoError(p.string() + ": cannot be read (" + status_error.message() + ")");
    }
    if (!fs::is_regular_file(st))
      throw IoError(p.string() + ": " + (fs::is_directory(st) ? "a directory" : "not a regular file") +
                    " named like a slice; every .tif in a slice folder is a slice");
    n = p.string();
  }
  return names;
}

// A number after KEY= on a line of an ImageJ description ("channels=2\n"), or 1.
int64_t imagej_count(const std::string& description, const std::string& key) {
  for (size_t at = description.find(key + "="); at != std::string::npos; at = description.find(key + "=", at + 1)) {
    if (at != 0 && description[at - 1] != '\n') continue;
    return std::max<int64_t>(1, std::atoll(description.c_str() + at + key.size() + 1));
  }
  return 1;
}

// A count attribute of an OME-XML description (SizeC="2"), or 1; the attribute's whole name, not
// the end of another's (PhysicalSizeZ="0.3" is no SizeZ).
int64_t ome_count(const std::string& description, const std::string& attribute) {
  const std::string key = attribute + "=\"";
  for (size_t at = description.find(key); at != std::string::npos; at = description.find(key, at + 1))
    if (at > 0 && std::isspace(static_cast<unsigned char>(description[at - 1])))
      return std::max<int64_t>(1, std::atoll(description.c_str() + at + key.size()));
  return 1;
}

// A multi-page file whose pages are not one channel's slices in order: an ImageJ hyperstack or an
// OME-TIFF whose pages interleave channels, or time points of several slices each. Read page by
// page they would be stacked as one volume, silently wrong.
void refuse_interleaved_pages(const TiffFile& file) {
  char* text = nullptr;
  if (!TIFFGetField(file.get(), TIFFTAG_IMAGEDESCRIPTION, &text) || text == nullptr) return;
  const std::string d(text, strnlen(text, 1 << 20));
  int64_t channels = 1, slices = 1, frames = 1;
  if (d.rfind("ImageJ=", 0) == 0) {
    channels = imagej_count(d, "channels"), slices = imagej_count(d, "slices"), frames = imagej_count(d, "frames");
  } else if (d.find("<OME") != std::string::npos) {
    channels = ome_count(d, "SizeC"), slices = ome_count(d, "SizeZ"), frames = ome_count(d, "SizeT");
  }
  if (channels > 1)
    file.fail("a hyperstack of " + std::to_string(channels) +
              " channels, whose pages interleave them; isotope reads one channel: save each channel as its own "
              "stack (in Fiji: Image > Color > Split Channels)");
  if (slices > 1 && frames > 1)
    file.fail("a hyperstack of " + std::to_string(frames) + " time points of " + std::to_string(slices) +
              " slices each; isotope reads one volume: save one time point as its own stack");
}

Stack open_stack(const std::string& path) {
  Stack s;
  s.where = path;
  std::error_code ec;
  if (fs::is_directory(path, ec)) {
    s.files = folder_slices(path);
    for (size_t z = 0; z < s.files.size(); ++z) {
      const TiffFile file(s.files[z], s.files[z]);
      const PageFormat f = page_format(file);
      check_page_data(file, f, "slice");
      if (z == 0) s.format = f;
      if (f != s.format)
        file.fail("a slice of " + describe(f) + ", where " + s.files[0] + " is " + describe(s.format) +
                  ": every slice of a stack has the same size and type");
      if (TIFFReadDirectory(file.get()))
        file.fail("more than one page; in a folder stack each file is one slice (name a multi-page file alone)");
      if (file.had_error()) file.fail("a damaged directory");
    }
    s.pages = static_cast<int64_t>(s.files.size());
  } else {
    s.files = {path};
    s.multipage = true;
    const TiffFile file(path, path);
    refuse_interleaved_pages(file);
    uint64_t claimed = 0;  // the pages' values, in bytes: pages may share their strips
    do {
      const PageFormat f = page_format(file);
      claimed += check_page_data(file, f, "page " + std::to_string(s.pages));
      s.directories.push_back(TIFFCurrentDirOffset(file.get()));
      if (claimed / max_expansion(COMPRESSION_LZMA) > file.size())
        file.fail("its pages claim " + std::to_string(claimed) + " bytes of values, more than " +
                  std::to_string(file.size()) + " bytes could hold (pages sharing their strips?)");
      if (s.pages == 0) s.format = f;
      if (f != s.format)
        file.fail("page " + std::to_string(s.pages) + " is " + describe(f) + ", where page 0 is " + describe(s.format) +
                  ": every page of a stack has the same size and type");
      ++s.pages;
    } while (TIFFReadDirectory(file.get()));
    if (file.had_error()) file.fail("page " + std::to_string(s.pages) + " cannot be read");
  }
  return s;
}

class TiffBoxReader final : public BoxReader {
 public:
  explicit TiffBoxReader(Stack stack) : stack_(std::move(stack)) {
    info_.dims = {stack_.format.width, stack_.format.height, stack_.pages};
    info_.type = scalar_type_name(stack_.format.type);
    info_.element_bytes = scalar_type_size(stack_.format.type);
    info_.is_integer = stack_.format.type != ScalarType::float32 && stack_.format.type != ScalarType::float64;
    checked_node_count(info_.dims, static_cast<int>(sizeof(float)), stack_.where);
  }

  void read_box(const std::array<int64_t, 3>& lo, const std::array<int64_t, 3>& size, float* out) const override {
    read_box_unchecked(lo, size, out);
    if (!info_.is_integer) check_finite(out, lo, size, stack_.where);  // an integer is finite as float
  }

  void read_box_unchecked(const std::array<int64_t, 3>& lo, const std::array<int64_t, 3>& size,
                          float* out) const override {
    const ScalarType type = stack_.format.type;
    constexpr bool big = std::endian::native == std::endian::big;  // libtiff hands over native order
    read_pages(lo, size, [&](const unsigned char* run, int64_t count, int64_t at) {
      decode_scalars(type, big, run, static_cast<size_t>(count), out + at);
    });
  }

  // Integers of one or two bytes, as libtiff hands them over: in this machine's byte order.
  std::optional<ScalarType> stored_type() const override {
    const ScalarType t = stack_.format.type;
    if (t == ScalarType::uint8 || t == ScalarType::uint16 || t == ScalarType::int16) return t;
    return std::nullopt;
  }

  void read_box_stored(const std::array<int64_t, 3>& lo, const std::array<int64_t, 3>& size,
                       unsigned char* out) const override {
    if (!stored_type()) throw std::logic_error(stack_.where + ": values cannot be read as stored");
    const auto eb = static_cast<size_t>(info_.element_bytes);
    read_pages(lo, size, [&](const unsigned char* run, int64_t count, int64_t at) {
      std::memcpy(out + static_cast<size_t>(at) * eb, run, static_cast<size_t>(count) * eb);
    });
  }

 private:
  // The box, page by page: put(run, count, at) for each run of COUNT elements of a row, decoded
  // in the page's type and this machine's byte order at RUN, whose first is the box's node AT
  // (x fastest).
  template <class Put>
  void read_pages(const std::array<int64_t, 3>& lo, const std::array<int64_t, 3>& size, const Put& put) const {
    check_box(lo, size, info_, stack_.where);
    if (size[0] * size[1] * size[2] == 0) return;
    std::optional<TiffFile> multipage;  // one handle per call: concurrent boxes share nothing
    if (stack_.multipage) multipage.emplace(stack_.files[0], stack_.where);
    std::vector<unsigned char> buffer;
    for (int64_t k = 0; k < size[2]; ++k) {
      const int64_t z = lo[2] + k;
      const int64_t slice = k * size[0] * size[1];
      if (multipage) {
        if (!TIFFSetSubDirectory(multipage->get(), stack_.directories[static_cast<size_t>(z)]))
          multipage->fail("page " + std::to_string(z) + " cannot be read");
        if (page_format(*multipage) != stack_.format)  // the file may have been replaced since
          multipage->fail("page " + std::to_string(z) + " changed since the stack was opened");
        read_rows(*multipage, lo, size, slice, buffer, "page " + std::to_string(z), put);
        multipage->refuse_guessed_data("page " + std::to_string(z));
      } else {
        const TiffFile file(stack_.files[static_cast<size_t>(z)], stack_.files[static_cast<size_t>(z)]);
        // The file may have been replaced since the stack was opened.
        if (page_format(file) != stack_.format) file.fail("changed since the stack was opened");
        read_rows(file, lo, size, slice, buffer, "slice", put);
        file.refuse_guessed_data("slice");
      }
    }
  }

  // Rows lo[1] .. lo[1]+size[1]-1, columns lo[0] .. lo[0]+size[0]-1 of the current page, the box's
  // nodes from SLICE on, decoding the strips or tiles they lie in.
  template <class Put>
  void read_rows(const TiffFile& file, const std::array<int64_t, 3>& lo, const std::array<int64_t, 3>& size,
                 int64_t slice, std::vector<unsigned char>& buffer, const std::string& page, const Put& put) const {
    TIFF* tif = file.get();
    const ScalarType type = stack_.format.type;
    const int64_t eb = scalar_type_size(type), width = stack_.format.width, height = stack_.format.height;
    const int64_t x0 = lo[0], x1 = lo[0] + size[0], y0 = lo[1], y1 = lo[1] + size[1];
    // A block of BW x BH elements at (BX, BY) decoded in `buffer`: its part inside the box.
    const auto copy_block = [&](int64_t bx, int64_t by, int64_t bw, int64_t bh) {
      const int64_t cx0 = std::max(x0, bx), cx1 = std::min(x1, bx + bw);
      for (int64_t y = std::max(y0, by); y < std::min(y1, by + bh); ++y)
        put(buffer.data() + ((y - by) * bw + (cx0 - bx)) * eb, cx1 - cx0, slice + (y - y0) * size[0] + (cx0 - x0));
    };
    if (TIFFIsTiled(tif)) {
      uint32_t tw = 0, th = 0;
      if (!TIFFGetField(tif, TIFFTAG_TILEWIDTH, &tw) || !TIFFGetField(tif, TIFFTAG_TILELENGTH, &th) || tw == 0 ||
          th == 0)
        file.fail(page + ": tiles without a size");
      const tmsize_t need = static_cast<tmsize_t>(tw) * th * eb;
      if (need > kMaxTiffAllocation) file.fail(page + ": tiles of more than 256 MB");
      buffer.resize(static_cast<size_t>(std::max(need, TIFFTileSize(tif))));
      for (int64_t ty = y0 / th * th; ty < y1; ty += th)
        for (int64_t tx = x0 / tw * tw; tx < x1; tx += tw) {
          const uint32_t tile = TIFFComputeTile(tif, static_cast<uint32_t>(tx), static_cast<uint32_t>(ty), 0, 0);
          if (TIFFReadEncodedTile(tif, tile, buffer.data(), static_cast<tmsize_t>(buffer.size())) < need)
            file.fail(page + ": tile " + std::to_string(tile) + " cannot be read");
          copy_block(tx, ty, tw, th);
        }
    } else {
      uint32_t rows = 0;
      TIFFGetFieldDefaulted(tif, TIFFTAG_ROWSPERSTRIP, &rows);
      const int64_t rps = std::clamp<int64_t>(rows, 1, height);
      if (rps * width * eb > kMaxTiffAllocation) file.fail(page + ": strips of more than 256 MB");
      buffer.resize(static_cast<size_t>(rps * width * eb));
      for (int64_t sy = y0 / rps * rps; sy < y1; sy += rps) {
        const int64_t strip_rows = std::min(rps, height - sy);
        const tstrip_t strip = TIFFComputeStrip(tif, static_cast<uint32_t>(sy), 0);
        if (TIFFReadEncodedStrip(tif, strip, buffer.data(), static_cast<tmsize_t>(buffer.size())) <
            strip_rows * width * eb)
          file.fail(page + ": strip " + std::to_string(strip) + " cannot be read");
        copy_block(0, sy, width, strip_rows);
      }
    }
  }

  Stack stack_;
};

}  // namespace

bool is_tiff_stack(const std::string& path) {
  std::error_code ec;
  return has_tiff_extension(path) || fs::is_directory(path, ec);
}

std::unique_ptr<BoxReader> open_tiff_stack(const std::string& path) {
  return std::make_unique<TiffBoxReader>(open_stack(path));
}

Volume read_tiff_stack(const std::string& path) {
  const std::unique_ptr<BoxReader> reader = open_tiff_stack(path);
  Volume v;
  v.dims = reader->info().dims;
  v.spacing = reader->info().spacing;
  v.origin = reader->info().origin;
  detail::resize_prefaulted_in_parallel(v.values, static_cast<size_t>(v.node_count()));
  reader->read_box({0, 0, 0}, v.dims, v.values.data());
  return v;
}

}  // namespace isotope
