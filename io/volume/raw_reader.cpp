#include "io/volume/raw_reader.h"

#include <algorithm>
#include <bit>
#include <cctype>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <limits>
#include <memory>
#include <new>
#include <sstream>
#include <system_error>
#include <type_traits>
#include <vector>

#include "engine/core/huge_blocks.h"
#include "engine/core/parallel.h"
#include "engine/core/volume_check.h"
#include "io/file/checked_size.h"
#include "io/file/input_file.h"
#include "io/file/positioned_io.h"
#include "io/volume/raw_data_reader.h"
#include "isotope/error.h"

namespace isotope {
namespace {

namespace fs = std::filesystem;

std::string lowercase(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return s;
}

std::optional<int64_t> parse_dim(const std::string& token) {
  int64_t v = 0;
  const char* end = token.data() + token.size();
  const auto [ptr, ec] = std::from_chars(token.data(), end, v);
  if (ec != std::errc() || ptr != end || v < 1) return std::nullopt;
  return v;
}

std::string dims_text(const std::array<int64_t, 3>& d) {
  return std::to_string(d[0]) + "x" + std::to_string(d[1]) + "x" + std::to_string(d[2]);
}

template <typename T>
float to_float(T v) {
  // A double beyond float range has no defined conversion; infinity lets check_finite report it.
  if constexpr (std::is_same_v<T, double>) {
    if (std::fabs(v) > std::numeric_limits<float>::max())
      return v > 0 ? std::numeric_limits<float>::infinity() : -std::numeric_limits<float>::infinity();
  }
  return static_cast<float>(v);
}

template <typename T, bool kSwap>
void decode(const unsigned char* in, size_t count, float* out) {
  for (size_t i = 0; i < count; ++i) {
    std::array<unsigned char, sizeof(T)> b;
    std::memcpy(b.data(), in + i * sizeof(T), sizeof(T));
    if constexpr (kSwap) std::reverse(b.begin(), b.end());
    out[i] = to_float(std::bit_cast<T>(b));
  }
}

template <typename T>
void decode(bool swap, const unsigned char* in, size_t count, float* out) {
  swap ? decode<T, true>(in, count, out) : decode<T, false>(in, count, out);
}

// Blocks of values read (pread) and converted on all threads: a 256^3 uint8 volume took 31 ms on
// one, the largest share of a one-shot extraction after the marching itself.
void read_values(const std::string& path, ScalarType type, std::vector<float>& values) {
  const FileDescriptor file = open_input(path, path, "a volume file");
  const size_t elem = static_cast<size_t>(scalar_type_size(type));
  constexpr size_t kBlockValues = size_t{1} << 18;  // bounds each task's staging buffer to 2 MiB
  const auto blocks = static_cast<int64_t>((values.size() + kBlockValues - 1) / kBlockValues);
  parallel_for(int64_t{0}, blocks, [&](int64_t b) {
    const size_t first = static_cast<size_t>(b) * kBlockValues, n = std::min(kBlockValues, values.size() - first);
    // Page-aligned, as the blocks' offsets are: the kernel's copy into it then needs no bounce
    // (docs/METHOD.md, "Reading and writing files"). Written whole by each read: not zero-filled.
    thread_local const detail::PageAlignedArray<unsigned char> buffer =
        detail::make_page_aligned<unsigned char>(kBlockValues * sizeof(double));
    const size_t bytes = n * elem;
    const PreadOutcome r = pread_all(file.get(), buffer.get(), bytes, first * elem);
    if (r.bytes < bytes) {
      const std::string why = r.error != 0 ? std::strerror(r.error) : "unexpected end of file";
      throw IoError(path + ": read failed after " + std::to_string(first * elem + r.bytes) + " bytes: " + why);
    }
    decode_scalars(type, false, buffer.get(), n, values.data() + first);
  });
}

}  // namespace

std::optional<std::array<int64_t, 3>> parse_dims(const std::string& token) {
  std::array<int64_t, 3> dims{};
  size_t start = 0;
  for (int axis = 0; axis < 3; ++axis) {
    const size_t x = axis < 2 ? token.find('x', start) : token.size();
    if (x == std::string::npos) return std::nullopt;
    const auto d = parse_dim(token.substr(start, x - start));
    if (!d) return std::nullopt;
    dims[axis] = *d;
    start = x + 1;
  }
  return dims;
}

std::optional<ScalarType> parse_scalar_type(const std::string& name) {
  const std::string n = lowercase(name);
  if (n == "uint8" || n == "u8") return ScalarType::uint8;
  if (n == "uint16" || n == "u16") return ScalarType::uint16;
  if (n == "int16" || n == "i16") return ScalarType::int16;
  if (n == "float32" || n == "f32" || n == "float") return ScalarType::float32;
  if (n == "float64" || n == "f64" || n == "double") return ScalarType::float64;
  return std::nullopt;
}

const char* scalar_type_name(ScalarType t) {
  switch (t) {
    case ScalarType::uint8: return "uint8";
    case ScalarType::uint16: return "uint16";
    case ScalarType::int16: return "int16";
    case ScalarType::float32: return "float32";
    case ScalarType::float64: return "float64";
  }
  return "unknown";
}

int scalar_type_size(ScalarType t) {
  switch (t) {
    case ScalarType::uint8: return 1;
    case ScalarType::uint16: return 2;
    case ScalarType::int16: return 2;
    case ScalarType::float32: return 4;
    case ScalarType::float64: return 8;
  }
  return 1;
}

std::optional<RawLayout> parse_raw_name(const std::string& path) {
  // The layout is the last two '_' tokens of the stem: NAME_XxYxZ_TYPE.ext
  const std::string stem = lowercase(fs::path(path).stem().string());
  const size_t type_sep = stem.rfind('_');
  if (type_sep == std::string::npos || type_sep == 0) return std::nullopt;
  const size_t dims_sep = stem.rfind('_', type_sep - 1);
  const size_t dims_start = dims_sep == std::string::npos ? 0 : dims_sep + 1;
  const auto type = parse_scalar_type(stem.substr(type_sep + 1));
  const auto dims = parse_dims(stem.substr(dims_start, type_sep - dims_start));
  if (!type || !dims) return std::nullopt;
  return RawLayout{*dims, *type};
}

int64_t checked_node_count(const std::array<int64_t, 3>& dims, int element_bytes, const std::string& file) {
  for (int64_t d : dims) {
    if (d < 1) throw IoError(file + ": dimensions " + dims_text(dims) + " invalid, each must be >= 1");
  }
  std::optional<int64_t> count = int64_t{1};
  for (int64_t d : dims)
    if (count) count = checked_mul(*count, d);
  // The byte count must fit too, since callers form count * element_bytes.
  if (!count || !checked_mul(*count, int64_t{std::max(element_bytes, 1)}))
    throw IoError(file + ": dimensions " + dims_text(dims) + " too large");
  return *count;
}

void check_volume_layout(const std::array<int64_t, 3>& dims, const std::array<double, 3>& spacing,
                         const std::array<double, 3>& origin, const std::string& file) {
  try {
    validate_layout(dims, spacing, origin);
  } catch (const InvalidInput& e) {
    throw IoError(file + ": " + e.what());
  }
}

void check_finite(const Volume& volume, const std::string& file) {
  check_finite(volume.data(), {0, 0, 0}, volume.dims, file);
}

void check_finite(const float* values, const std::array<int64_t, 3>& lo, const std::array<int64_t, 3>& size,
                  const std::string& file) {
  const int64_t count = size[0] * size[1] * size[2];
  const auto i = static_cast<int64_t>(first_non_finite(values, static_cast<size_t>(count)));
  if (i == count) return;
  const float* bad = values + i;
  const int64_t nx = size[0], ny = size[1];
  std::ostringstream msg;
  msg << file << ": value " << *bad << " at (x,y,z) = (" << lo[0] + i % nx << "," << lo[1] + (i / nx) % ny << ","
      << lo[2] + i / (nx * ny) << ") is not finite (NaN, infinite, or beyond float range)";
  throw IoError(msg.str());
}

void decode_scalars(ScalarType type, bool big_endian, const unsigned char* in, size_t count, float* out) {
  const bool swap = big_endian != (std::endian::native == std::endian::big);
  switch (type) {
    case ScalarType::uint8: decode<uint8_t>(false, in, count, out); break;
    case ScalarType::uint16: decode<uint16_t>(swap, in, count, out); break;
    case ScalarType::int16: decode<int16_t>(swap, in, count, out); break;
    case ScalarType::float32: decode<float>(swap, in, count, out); break;
    case ScalarType::float64: decode<double>(swap, in, count, out); break;
  }
}

int64_t check_raw_file(const std::string& path, const RawLayout& layout) {
  const int elem = scalar_type_size(layout.type);
  const int64_t expected_bytes = checked_node_count(layout.dims, elem, path) * elem;
  // Distinguishes "missing" from "a directory" from "wrong size" before any allocation.
  require_regular_file(path, path, "a volume file");
  std::error_code ec;
  const auto size = fs::file_size(path, ec);
  if (ec) throw IoError(path + ": cannot determine file size: " + ec.message());
  if (static_cast<int64_t>(size) != expected_bytes) {
    throw IoError(path + ": size " + std::to_string(size) + " bytes, expected " + std::to_string(expected_bytes) +
                  " for " + dims_text(layout.dims) + " " + scalar_type_name(layout.type));
  }
  return expected_bytes;
}

Volume read_raw(const std::string& path, const RawLayout& layout) {
  const int64_t count = check_raw_file(path, layout) / scalar_type_size(layout.type);
  Volume volume;
  volume.dims = layout.dims;
  try {
    detail::resize_prefaulted_in_parallel(volume.values, static_cast<size_t>(count));
  } catch (const std::bad_alloc&) {
    throw IoError(path + ": " + dims_text(layout.dims) + " volume does not fit in memory");
  }
  read_values(path, layout.type, volume.values);
  if (layout.type == ScalarType::float32 || layout.type == ScalarType::float64) check_finite(volume, path);
  return volume;
}

std::unique_ptr<BoxReader> open_raw_box_reader(const std::string& path, const RawLayout& layout) {
  check_raw_file(path, layout);
  const VolumeInfo info = volume_info(layout.type, layout.dims, {1, 1, 1}, {0, 0, 0});
  return open_raw_data(open_input(path, path, "a volume file"), RawData{0, layout.type, false, path, path}, info);
}

}  // namespace isotope
