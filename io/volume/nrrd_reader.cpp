#include "io/volume/nrrd_reader.h"

#include <unistd.h>
#include <zlib.h>

#include <algorithm>
#include <array>
#include <cctype>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <limits>
#include <memory>
#include <new>
#include <optional>
#include <sstream>
#include <system_error>
#include <vector>

#include "engine/core/huge_blocks.h"
#include "io/file/input_file.h"
#include "io/volume/raw_data_reader.h"
#include "io/volume/raw_reader.h"
#include "isotope/error.h"

namespace isotope {
namespace {

namespace fs = std::filesystem;

// The header fields isotope uses, each validated as it is read; the rest are ignored.
struct NrrdHeader {
  std::optional<std::array<int64_t, 3>> sizes;
  std::optional<ScalarType> type;
  std::optional<NrrdEncoding> encoding;
  std::optional<bool> big_endian;
  std::optional<std::array<double, 3>> spacings;
  std::optional<std::array<double, 3>> direction_lengths;
  std::optional<std::array<double, 3>> origin;
  std::optional<std::string> data_file;
  bool has_dimension = false;
  int64_t byte_skip = 0;
  int64_t line_skip = 0;
  bool ends_with_blank_line = false;  // attached data can only follow a blank line
};

constexpr size_t kMaxHeaderLine = size_t{1} << 16;  // a binary file without newlines stops here
constexpr size_t kBlockBytes = size_t{1} << 20;     // a whole number of values of every type
constexpr size_t kGzipInputChunk = size_t{1} << 16;

struct FileCloser {
  void operator()(std::FILE* f) const { std::fclose(f); }
};
using FilePtr = std::unique_ptr<std::FILE, FileCloser>;

// ---------------------------------------------------------------- text

std::string trim(const std::string& s) {
  const auto is_space = [](unsigned char c) { return std::isspace(c) != 0; };
  const auto begin = std::find_if_not(s.begin(), s.end(), is_space);
  const auto end = std::find_if_not(s.rbegin(), s.rend(), is_space).base();
  return begin < end ? std::string(begin, end) : std::string();
}

std::vector<std::string> words(const std::string& s) {
  std::istringstream in(s);
  std::vector<std::string> out;
  for (std::string w; in >> w;) out.push_back(w);
  return out;
}

// Lowercase words joined by one space: "Unsigned  Short" -> "unsigned short".
std::string normalized(const std::string& s) {
  std::string out;
  for (const auto& w : words(s)) out += (out.empty() ? "" : " ") + w;
  std::transform(out.begin(), out.end(), out.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return out;
}

// Teem accepts field names with or without their inner spaces ("byte skip", "byteskip").
std::string field_key(const std::string& name) {
  std::string key;
  for (unsigned char c : name) {
    if (!std::isspace(c)) key.push_back(static_cast<char>(std::tolower(c)));
  }
  return key;
}

// A header line as quoted in a message: binary junk is cut short.
std::string quoted(const std::string& s) { return "'" + (s.size() > 60 ? s.substr(0, 60) + "..." : s) + "'"; }

std::optional<int64_t> parse_int(const std::string& token) {
  int64_t v = 0;
  const char* end = token.data() + token.size();
  const auto [ptr, ec] = std::from_chars(token.data(), end, v);
  if (ec != std::errc() || ptr != end || token.empty()) return std::nullopt;
  return v;
}

std::optional<double> parse_double(const std::string& token) {
  double v = 0;
  const char* end = token.data() + token.size();
  const auto [ptr, ec] = std::from_chars(token.data(), end, v);
  if (ec != std::errc() || ptr != end || token.empty()) return std::nullopt;
  return v;
}

// "1, 2.5,-3" -> {1, 2.5, -3}; exactly three numbers.
std::optional<std::array<double, 3>> parse_xyz(const std::string& inner) {
  std::array<double, 3> v{};
  size_t start = 0;
  for (size_t axis = 0; axis < 3; ++axis) {
    const size_t comma = axis < 2 ? inner.find(',', start) : inner.size();
    if (comma == std::string::npos) return std::nullopt;
    const auto c = parse_double(trim(inner.substr(start, comma - start)));
    if (!c) return std::nullopt;
    v[axis] = *c;
    start = comma + 1;
  }
  return v;
}

// "(1,0,0) (0,2,0)" -> the vectors; nullopt when any is malformed or not 3-D ("none" included).
std::optional<std::vector<std::array<double, 3>>> parse_vectors(const std::string& text) {
  std::vector<std::array<double, 3>> out;
  for (size_t pos = 0; (pos = text.find_first_not_of(" \t", pos)) != std::string::npos;) {
    const size_t close = text.find(')', pos);
    if (text[pos] != '(' || close == std::string::npos) return std::nullopt;
    const auto v = parse_xyz(text.substr(pos + 1, close - pos - 1));
    if (!v) return std::nullopt;
    out.push_back(*v);
    pos = close + 1;
  }
  return out;
}

// ---------------------------------------------------------------- fields

[[noreturn]] void bad_field(const std::string& path, const char* field, const std::string& value,
                            const std::string& why) {
  throw IoError(path + ": " + field + " " + quoted(value) + " " + why);
}

void set_dimension(NrrdHeader& h, const std::string& v, const std::string& path) {
  const auto d = parse_int(v);
  if (!d) bad_field(path, "dimension", v, "is not an integer");
  if (*d != 3) bad_field(path, "dimension", v, "not supported; isotope reads 3-D volumes only");
  h.has_dimension = true;
}

void set_sizes(NrrdHeader& h, const std::string& v, const std::string& path) {
  const auto w = words(v);
  if (w.size() != 3) bad_field(path, "sizes", v, "must be 3 integers >= 1");
  std::array<int64_t, 3> sizes{};
  for (size_t axis = 0; axis < 3; ++axis) {
    const auto s = parse_int(w[axis]);
    if (!s || *s < 1) bad_field(path, "sizes", v, "must be 3 integers >= 1");
    sizes[axis] = *s;
  }
  h.sizes = sizes;
}

void set_type(NrrdHeader& h, const std::string& v, const std::string& path) {
  struct Spelling {
    const char* name;
    ScalarType type;
  };
  // Teem's spellings of the five types isotope reads (format.html, "type").
  static constexpr Spelling kSpellings[] = {
      {"uchar", ScalarType::uint8},
      {"unsigned char", ScalarType::uint8},
      {"uint8", ScalarType::uint8},
      {"uint8_t", ScalarType::uint8},
      {"short", ScalarType::int16},
      {"short int", ScalarType::int16},
      {"signed short", ScalarType::int16},
      {"signed short int", ScalarType::int16},
      {"int16", ScalarType::int16},
      {"int16_t", ScalarType::int16},
      {"ushort", ScalarType::uint16},
      {"unsigned short", ScalarType::uint16},
      {"unsigned short int", ScalarType::uint16},
      {"uint16", ScalarType::uint16},
      {"uint16_t", ScalarType::uint16},
      {"float", ScalarType::float32},
      {"double", ScalarType::float64},
  };
  const std::string name = normalized(v);
  for (const auto& s : kSpellings) {
    if (name == s.name) {
      h.type = s.type;
      return;
    }
  }
  bad_field(path, "type", v, "not supported; expected uchar, short, ushort, float or double");
}

void set_encoding(NrrdHeader& h, const std::string& v, const std::string& path) {
  const std::string name = normalized(v);
  if (name == "raw") {
    h.encoding = NrrdEncoding::raw;
  } else if (name == "gzip" || name == "gz") {
    h.encoding = NrrdEncoding::gzip;
  } else {
    bad_field(path, "encoding", v, "not supported; expected raw or gzip");
  }
}

void set_endian(NrrdHeader& h, const std::string& v, const std::string& path) {
  const std::string name = normalized(v);
  if (name != "little" && name != "big") bad_field(path, "endian", v, "must be little or big");
  h.big_endian = name == "big";
}

void set_spacings(NrrdHeader& h, const std::string& v, const std::string& path) {
  // "nan" marks a non-spatial axis in NRRD; all three axes of a volume are spatial.
  const auto w = words(v);
  if (w.size() != 3) bad_field(path, "spacings", v, "must be 3 finite numbers > 0");
  std::array<double, 3> s{};
  for (size_t axis = 0; axis < 3; ++axis) {
    s[axis] = parse_double(w[axis]).value_or(0);
    if (!std::isfinite(s[axis]) || s[axis] <= 0) bad_field(path, "spacings", v, "must be 3 finite numbers > 0");
  }
  h.spacings = s;
}

// Only the lengths are kept: Volume is axis-aligned, so a rotated or sheared grid is read as if
// its axes were x, y, z (positions of the mesh are then in the grid's own frame).
void set_space_directions(NrrdHeader& h, const std::string& v, const std::string& path) {
  const auto vectors = parse_vectors(v);
  if (!vectors || vectors->size() != 3) bad_field(path, "space directions", v, "must be 3 vectors (x,y,z)");
  std::array<double, 3> lengths{};
  for (size_t axis = 0; axis < 3; ++axis) {
    const auto& d = (*vectors)[axis];
    lengths[axis] = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
    if (!std::isfinite(lengths[axis]) || lengths[axis] <= 0)
      bad_field(path, "space directions", v, "must have finite, nonzero lengths");
  }
  h.direction_lengths = lengths;
}

void set_space_origin(NrrdHeader& h, const std::string& v, const std::string& path) {
  const auto vectors = parse_vectors(v);
  const bool valid =
      vectors && vectors->size() == 1 &&
      std::all_of(vectors->front().begin(), vectors->front().end(), [](double d) { return std::isfinite(d); });
  if (!valid) bad_field(path, "space origin", v, "must be one vector (x,y,z) of finite numbers");
  h.origin = vectors->front();
}

void set_data_file(NrrdHeader& h, const std::string& v, const std::string& path) {
  // "LIST" and "FORMAT MIN MAX STEP" spread the data over several files.
  const auto w = words(v);
  if (w.empty() || w.front() == "LIST" || v.find('%') != std::string::npos)
    bad_field(path, "data file", v, "not supported; expected one file name");
  h.data_file = v;
}

void set_byte_skip(NrrdHeader& h, const std::string& v, const std::string& path) {
  const auto n = parse_int(v);
  if (!n || *n < -1) bad_field(path, "byte skip", v, "must be an integer >= -1");
  h.byte_skip = *n;
}

void set_line_skip(NrrdHeader& h, const std::string& v, const std::string& path) {
  const auto n = parse_int(v);
  if (!n || *n < 0) bad_field(path, "line skip", v, "must be an integer >= 0");
  h.line_skip = *n;
}

using FieldSetter = void (*)(NrrdHeader&, const std::string&, const std::string&);
struct Field {
  const char* key;  // field_key() of the NRRD field name
  FieldSetter set;
};
constexpr Field kFields[] = {
    {"dimension", set_dimension},
    {"sizes", set_sizes},
    {"type", set_type},
    {"encoding", set_encoding},
    {"endian", set_endian},
    {"spacings", set_spacings},
    {"spacedirections", set_space_directions},
    {"spaceorigin", set_space_origin},
    {"datafile", set_data_file},
    {"byteskip", set_byte_skip},
    {"lineskip", set_line_skip},
};

// ---------------------------------------------------------------- header

// One line without its "\n" or "\r\n"; nullopt at the end of the file.
std::optional<std::string> read_line(std::FILE* f, const std::string& path) {
  std::string line;
  int c = 0;
  while ((c = std::fgetc(f)) != EOF && c != '\n') {
    if (line.size() == kMaxHeaderLine)
      throw IoError(path + ": header line longer than " + std::to_string(kMaxHeaderLine) + " bytes");
    line.push_back(static_cast<char>(c));
  }
  if (std::ferror(f)) throw IoError(path + ": read failed: " + std::strerror(errno));
  if (c == EOF && line.empty()) return std::nullopt;
  if (!line.empty() && line.back() == '\r') line.pop_back();
  return line;
}

// The first 8 bytes decide, so a binary file is never scanned for a newline.
void check_magic(std::FILE* f, const std::string& path) {
  std::array<char, 8> magic{};
  const std::string m(magic.data(), std::fread(magic.data(), 1, magic.size(), f));
  const bool valid = m.size() == 8 && m.compare(0, 7, "NRRD000") == 0 && m[7] >= '1' && m[7] <= '5';
  const auto rest = valid ? read_line(f, path) : std::nullopt;
  if (!valid || (rest && !rest->empty()))
    throw IoError(path + ": not an NRRD file (the first line is not NRRD0001 .. NRRD0005)");
}

void apply_line(NrrdHeader& h, const std::string& line, const std::string& path) {
  if (line.front() == '#') return;  // comment
  const size_t colon = line.find(": ");
  const size_t key_value = line.find(":=");
  if (key_value != std::string::npos && key_value < colon) return;  // "key:=value": nothing isotope uses
  if (colon == std::string::npos) throw IoError(path + ": header line " + quoted(line) + " is not 'field: value'");
  const std::string key = field_key(line.substr(0, colon));
  for (const Field& field : kFields) {
    if (key == field.key) return field.set(h, trim(line.substr(colon + 2)), path);
  }
}

NrrdHeader read_header(std::FILE* f, const std::string& path) {
  check_magic(f, path);
  NrrdHeader h;
  while (const auto line = read_line(f, path)) {
    if (line->empty()) {
      h.ends_with_blank_line = true;
      break;
    }
    apply_line(h, *line, path);
  }
  return h;
}

[[noreturn]] void missing_field(const std::string& path, const char* field) {
  throw IoError(path + ": header has no '" + field + "' field");
}

// What NRRD requires of the fields together, checked once the header is complete.
void check_header(const NrrdHeader& h, const std::string& path) {
  if (!h.has_dimension) missing_field(path, "dimension");
  if (!h.sizes) missing_field(path, "sizes");
  if (!h.type) missing_field(path, "type");
  if (!h.encoding) missing_field(path, "encoding");
  if (!h.big_endian && scalar_type_size(*h.type) > 1)
    throw IoError(path + ": header has no 'endian' field, required for " + scalar_type_name(*h.type) + " data");
  if (h.spacings && h.direction_lengths)
    throw IoError(path + ": header has both 'spacings' and 'space directions'; NRRD allows one");
  if (h.byte_skip == -1 && *h.encoding != NrrdEncoding::raw)
    throw IoError(path + ": 'byte skip: -1' is only allowed with raw encoding");
  if (!h.data_file && !h.ends_with_blank_line)
    throw IoError(path + ": header ends without the blank line that precedes attached data");
}

// ---------------------------------------------------------------- data sources

struct RawSource {
  std::FILE* file;
  const std::string& where;

  size_t read(unsigned char* out, size_t n) {
    const size_t got = std::fread(out, 1, n, file);
    if (got < n && std::ferror(file)) throw IoError(where + ": read failed: " + std::strerror(errno));
    return got;
  }
};

// Inflates FILE from its current position, reading it in chunks. 16 + MAX_WBITS makes zlib expect
// the gzip wrapper and check its CRC-32 and length when the stream ends.
class GzipSource {
 public:
  GzipSource(std::FILE* file, const std::string& where) : file_(file), where_(where) {
    if (inflateInit2(&zs_, 16 + MAX_WBITS) != Z_OK) throw IoError(where + ": cannot start gzip decompression");
  }
  ~GzipSource() { inflateEnd(&zs_); }
  GzipSource(const GzipSource&) = delete;
  GzipSource& operator=(const GzipSource&) = delete;

  // Fills OUT[0, N); fewer bytes only when the stream or the file ends first. N fits a uInt
  // because callers pass at most one staging block.
  size_t read(unsigned char* out, size_t n) {
    zs_.next_out = out;
    zs_.avail_out = static_cast<uInt>(n);
    while (zs_.avail_out > 0 && !ended_ && refill()) inflate_step();
    return n - zs_.avail_out;
  }

  // NRRD counts the byte skip of compressed data in decompressed bytes.
  void skip(int64_t bytes) {
    if (bytes == 0) return;
    std::vector<unsigned char> scratch(kGzipInputChunk);
    for (int64_t left = bytes; left > 0;) {
      const size_t n = static_cast<size_t>(std::min<int64_t>(left, static_cast<int64_t>(scratch.size())));
      if (read(scratch.data(), n) != n)
        throw IoError(where_ + ": data truncated: gzip data ends within the " + std::to_string(bytes) +
                      " bytes to skip");
      left -= static_cast<int64_t>(n);
    }
  }

  // Exactly the expected bytes: nothing more may come out, and the trailer must be there.
  void expect_end(size_t expected) {
    unsigned char extra = 0;
    if (read(&extra, 1) != 0)
      throw IoError(where_ + ": gzip data holds more than the " + std::to_string(expected) +
                    " bytes the header describes");
    if (!ended_) throw IoError(where_ + ": data truncated: gzip stream ends without its trailer");
  }

 private:
  // False when the file has no more input.
  bool refill() {
    if (zs_.avail_in > 0) return true;
    const size_t got = std::fread(input_.data(), 1, input_.size(), file_);
    if (got == 0 && std::ferror(file_)) throw IoError(where_ + ": read failed: " + std::strerror(errno));
    zs_.next_in = input_.data();
    zs_.avail_in = static_cast<uInt>(got);
    return got > 0;
  }

  void inflate_step() {
    const int rc = inflate(&zs_, Z_NO_FLUSH);
    if (rc == Z_STREAM_END) ended_ = true;
    if (rc == Z_OK || rc == Z_STREAM_END || rc == Z_BUF_ERROR) return;  // Z_BUF_ERROR: needs input
    throw IoError(where_ + ": corrupt gzip data (zlib: " + (zs_.msg ? zs_.msg : zError(rc)) + ")");
  }

  std::FILE* file_;
  const std::string& where_;
  z_stream zs_{};
  std::vector<unsigned char> input_ = std::vector<unsigned char>(kGzipInputChunk);
  bool ended_ = false;
};

template <typename Source>
void stream_blocks(Source& source, int64_t total, const NrrdBlockSink& sink, const std::string& where) {
  std::vector<unsigned char> block(static_cast<size_t>(std::min<int64_t>(total, kBlockBytes)));
  for (int64_t done = 0; done < total;) {
    const size_t n = static_cast<size_t>(std::min<int64_t>(total - done, kBlockBytes));
    const size_t got = source.read(block.data(), n);
    if (got != n) {
      throw IoError(where + ": data truncated: " + std::to_string(done + static_cast<int64_t>(got)) + " of " +
                    std::to_string(total) + " bytes");
    }
    sink(block.data(), n);
    done += static_cast<int64_t>(n);
  }
}

void skip_lines(std::FILE* f, int64_t lines, const std::string& where) {
  for (int64_t i = 0; i < lines; ++i) {
    int c = 0;
    while ((c = std::fgetc(f)) != EOF && c != '\n') {
    }
    if (c == EOF)
      throw IoError(where + ": data truncated: file ends within the " + std::to_string(lines) + " lines to skip");
  }
}

// Bytes from the current position to the end of the file; 0 when a skip went past the end.
int64_t remaining_bytes(std::FILE* f, const std::string& where) {
  const long here = std::ftell(f);
  if (here < 0 || std::fseek(f, 0, SEEK_END) != 0) throw IoError(where + ": cannot seek: " + std::strerror(errno));
  const long end = std::ftell(f);
  if (end < 0 || std::fseek(f, here, SEEK_SET) != 0) throw IoError(where + ": cannot seek: " + std::strerror(errno));
  return std::max<int64_t>(0, end - here);
}

// Leaves F at the first data byte (raw) or compressed byte (gzip) after checking that the file can
// hold the data, so a header that lies about the sizes never causes a huge allocation.
void seek_data(std::FILE* f, const NrrdHeader& h, int64_t data_bytes, const std::string& where) {
  skip_lines(f, h.line_skip, where);  // lines of the file as stored, before any decompression
  if (*h.encoding == NrrdEncoding::gzip) {
    // Deflate expands at most 1032:1 (zlib FAQ), so fewer compressed bytes cannot hold the data.
    if (remaining_bytes(f, where) < data_bytes / 1032)
      throw IoError(where + ": data truncated: too little gzip data for " + std::to_string(data_bytes) + " bytes");
    return;
  }
  // "byte skip: -1" puts the data at the very end of the file, whatever precedes them.
  const int64_t skip = h.byte_skip >= 0 ? h.byte_skip : std::max<int64_t>(0, remaining_bytes(f, where) - data_bytes);
  if (std::fseek(f, static_cast<long>(skip), SEEK_CUR) != 0)
    throw IoError(where + ": cannot skip " + std::to_string(skip) + " bytes: " + std::strerror(errno));
  const int64_t left = remaining_bytes(f, where);
  if (left < data_bytes)
    throw IoError(where + ": data truncated: " + std::to_string(left) + " of " + std::to_string(data_bytes) + " bytes");
}

// ---------------------------------------------------------------- files

FilePtr open_file(const std::string& path, const std::string& where) {
  require_regular_file(path, where, "a volume file");
  FilePtr file(std::fopen(path.c_str(), "rb"));
  if (!file) throw IoError(where + ": cannot open: " + std::strerror(errno));
  return file;
}

// A relative data file is relative to the header's folder, not to the working directory.
std::string data_file_path(const std::string& header, const std::string& name) {
  const fs::path p(name);
  return p.is_absolute() ? p.string() : (fs::path(header).parent_path() / p).string();
}

Volume empty_volume(const NrrdLayout& layout, const std::string& path) {
  Volume volume;
  volume.dims = layout.dims;
  volume.spacing = layout.spacing;
  volume.origin = layout.origin;
  try {
    detail::resize_prefaulted_in_parallel(volume.values, static_cast<size_t>(volume.node_count()));
  } catch (const std::bad_alloc&) {
    throw IoError(path + ": volume of " + std::to_string(volume.node_count()) + " nodes does not fit in memory");
  }
  return volume;
}

// The header's fields as a layout; the data's position is filled in by the caller.
NrrdLayout layout_of(const NrrdHeader& h) {
  NrrdLayout layout;
  layout.encoding = *h.encoding;
  layout.type = *h.type;
  layout.big_endian = h.big_endian.value_or(false);  // single-byte types need no "endian" field
  layout.dims = *h.sizes;
  layout.spacing = h.spacings ? *h.spacings : h.direction_lengths.value_or(layout.spacing);
  layout.origin = h.origin.value_or(layout.origin);
  layout.inflated_skip = layout.encoding == NrrdEncoding::gzip ? h.byte_skip : 0;
  return layout;
}

}  // namespace

NrrdLayout read_nrrd_layout(const std::string& path) {
  const FilePtr header_file = open_file(path, path);
  const NrrdHeader h = read_header(header_file.get(), path);
  check_header(h, path);
  const int64_t count = checked_node_count(*h.sizes, scalar_type_size(*h.type), path);
  NrrdLayout layout = layout_of(h);
  // Detached data are named in messages as "HEADER: data file DATA" so both files are known.
  layout.data_path = h.data_file ? data_file_path(path, *h.data_file) : path;
  layout.where = h.data_file ? path + ": data file " + layout.data_path : path;
  const FilePtr detached = h.data_file ? open_file(layout.data_path, layout.where) : nullptr;
  std::FILE* data = detached ? detached.get() : header_file.get();
  seek_data(data, h, count * scalar_type_size(*h.type), layout.where);
  layout.data_offset = std::ftell(data);
  if (layout.data_offset < 0) throw IoError(layout.where + ": cannot tell position: " + std::strerror(errno));
  return layout;
}

void stream_nrrd_data(const NrrdLayout& layout, const NrrdBlockSink& sink) {
  const std::string& where = layout.where;
  const FilePtr file = open_file(layout.data_path, where);
  if (std::fseek(file.get(), static_cast<long>(layout.data_offset), SEEK_SET) != 0)
    throw IoError(where + ": cannot seek: " + std::strerror(errno));
  if (layout.encoding == NrrdEncoding::raw) {
    RawSource source{file.get(), where};
    return stream_blocks(source, layout.data_bytes(), sink, where);
  }
  GzipSource source(file.get(), where);
  source.skip(layout.inflated_skip);
  stream_blocks(source, layout.data_bytes(), sink, where);
  source.expect_end(static_cast<size_t>(layout.data_bytes()));
}

Volume read_nrrd(const std::string& path) {
  const NrrdLayout layout = read_nrrd_layout(path);
  Volume volume = empty_volume(layout, path);
  const size_t elem = static_cast<size_t>(scalar_type_size(layout.type));
  float* out = volume.values.data();
  stream_nrrd_data(layout, [&](const unsigned char* bytes, size_t size) {
    decode_scalars(layout.type, layout.big_endian, bytes, size / elem, out);
    out += size / elem;
  });
  check_finite(volume, path);
  return volume;
}

// ---------------------------------------------------------------- by boxes

namespace {

// The inflated copy of gzip data: a file created under a unique name in DIR, removed when this
// is destroyed.
class InflatedFile {
 public:
  // An empty DIR is the working directory, as everywhere else a relative path is.
  InflatedFile(const std::string& dir, const std::string& purpose)
      : path_((fs::path(dir) / "isotope-inflated-XXXXXX").string()),
        fd_(::mkostemp(path_.data(), O_CLOEXEC)) {  // fills in the X's
    if (fd_.get() < 0) {
      throw IoError((dir.empty() ? "." : dir) + ": cannot create a scratch file to " + purpose + ": " +
                    system_error_text(errno));
    }
  }
  ~InflatedFile() { ::unlink(path_.c_str()); }
  InflatedFile(const InflatedFile&) = delete;
  InflatedFile& operator=(const InflatedFile&) = delete;

  const std::string& path() const { return path_; }
  int fd() const { return fd_.get(); }

 private:
  std::string path_;
  FileDescriptor fd_;
};

void write_fully(int fd, const unsigned char* bytes, size_t size, const std::string& where) {
  for (size_t done = 0; done < size;) {
    const ssize_t n = ::write(fd, bytes + done, size - done);
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) {
      const int err = errno;
      const std::string text = system_error_text(err);
      throw IoError(where + ": write failed: " + (err == ENOSPC || err == EDQUOT ? "disk full (" + text + ")" : text));
    }
    done += static_cast<size_t>(n);
  }
}

// Inflated once into SCRATCH_DIR, with bounded memory, then read like raw NRRD data.
std::unique_ptr<BoxReader> open_gzip_nrrd(const NrrdLayout& layout, const VolumeInfo& info,
                                          const std::string& scratch_dir) {
  auto scratch = std::make_shared<const InflatedFile>(scratch_dir, "inflate " + layout.where);
  const std::string copy = layout.where + ": inflated copy " + scratch->path();
  stream_nrrd_data(layout,
                   [&](const unsigned char* bytes, size_t size) { write_fully(scratch->fd(), bytes, size, copy); });
  FileDescriptor fd = open_input(scratch->path(), copy, "a volume file");
  RawData data{0, layout.type, layout.big_endian, layout.where, copy};
  return open_raw_data(std::move(fd), std::move(data), info, std::move(scratch));
}

}  // namespace

std::unique_ptr<BoxReader> open_nrrd_box_reader(const std::string& path, const std::string& scratch_dir) {
  const NrrdLayout layout = read_nrrd_layout(path);  // also checks the file holds the data
  const VolumeInfo info = volume_info(layout.type, layout.dims, layout.spacing, layout.origin);
  if (layout.encoding == NrrdEncoding::gzip) return open_gzip_nrrd(layout, info, scratch_dir);
  RawData data{layout.data_offset, layout.type, layout.big_endian, layout.where, layout.where};
  return open_raw_data(open_input(layout.data_path, layout.where, "a volume file"), std::move(data), info);
}

}  // namespace isotope
