#include "io/volume/volume_writer.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <optional>
#include <span>
#include <vector>

#include "io/file/atomic_file.h"
#include "io/volume/hdf5_handle.h"
#include "io/volume/raw_reader.h"
#include "isotope/error.h"

namespace isotope {
namespace {

void check_shape(const Volume& volume, const std::string& path, int element_bytes) {
  const int64_t count = checked_node_count(volume.dims, element_bytes, path);
  if (static_cast<int64_t>(volume.size()) != count) {
    throw IoError(path + ": volume holds " + std::to_string(volume.size()) + " values but its dimensions need " +
                  std::to_string(count));
  }
}

struct CodeRange {
  double lo, hi;
};

// The codes an integer type offers; none for float types, which store values as they are.
std::optional<CodeRange> code_range(ScalarType type) {
  switch (type) {
    case ScalarType::uint8: return CodeRange{0, 255};
    case ScalarType::uint16: return CodeRange{0, 65535};
    case ScalarType::int16: return CodeRange{-32768, 32767};
    case ScalarType::float32:
    case ScalarType::float64: return std::nullopt;
  }
  return std::nullopt;
}

// IN as Bytes-wide little-endian words, whatever the host's byte order; BITS gives each word.
template <int Bytes, class Bits>
void encode_le(std::span<const float> in, unsigned char* out, Bits bits) {
  for (size_t i = 0; i < in.size(); ++i) {
    const uint64_t word = bits(in[i]);
    for (int k = 0; k < Bytes; ++k) out[i * Bytes + k] = static_cast<unsigned char>(word >> (8 * k));
  }
}

void encode_block(const RawEncoding& e, std::span<const float> in, unsigned char* out) {
  // The clamp only absorbs rounding at the ends: (max - min) * scale may exceed the span by an ulp.
  const CodeRange range = code_range(e.type).value_or(CodeRange{0, 0});
  const auto code = [&e, range](float v) {
    return static_cast<uint64_t>(static_cast<int64_t>(std::clamp(std::round(e.code(v)), range.lo, range.hi)));
  };
  switch (e.type) {
    case ScalarType::uint8: return encode_le<1>(in, out, code);
    case ScalarType::uint16:
    case ScalarType::int16: return encode_le<2>(in, out, code);
    case ScalarType::float32:
      return encode_le<4>(in, out, [](float v) { return uint64_t{std::bit_cast<uint32_t>(v)}; });
    case ScalarType::float64:
      return encode_le<8>(in, out, [](float v) { return std::bit_cast<uint64_t>(static_cast<double>(v)); });
  }
}

void write_xyz_attribute(hid_t ds, const char* name, const std::array<double, 3>& v, const std::string& path) {
  const hsize_t three = 3;
  const Hdf5Handle space(H5Screate_simple(1, &three, nullptr), H5Sclose);
  const Hdf5Handle attr(
      space ? H5Acreate2(ds, name, H5T_IEEE_F64LE, space.get(), H5P_DEFAULT, H5P_DEFAULT) : H5I_INVALID_HID, H5Aclose);
  if (!attr || H5Awrite(attr.get(), H5T_NATIVE_DOUBLE, v.data()) < 0)
    throw IoError(path + ": cannot write attribute '" + name + "': " + hdf5_error_detail());
}

void write_volume_dataset(hid_t file, const Volume& volume, const std::string& path) {
  const hsize_t zyx[3] = {static_cast<hsize_t>(volume.dims[2]), static_cast<hsize_t>(volume.dims[1]),
                          static_cast<hsize_t>(volume.dims[0])};
  const Hdf5Handle space(H5Screate_simple(3, zyx, nullptr), H5Sclose);
  const Hdf5Handle ds(
      space ? H5Dcreate2(file, "/volume", H5T_IEEE_F32LE, space.get(), H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT)
            : H5I_INVALID_HID,
      H5Dclose);
  if (!ds) throw IoError(path + ": cannot create dataset /volume: " + hdf5_error_detail());
  if (H5Dwrite(ds.get(), H5T_NATIVE_FLOAT, H5S_ALL, H5S_ALL, H5P_DEFAULT, volume.data()) < 0)
    throw IoError(path + ": cannot write dataset /volume: " + hdf5_error_detail());
  write_xyz_attribute(ds.get(), "spacing", volume.spacing, path);
  write_xyz_attribute(ds.get(), "origin", volume.origin, path);
}

}  // namespace

bool RawEncoding::is_mapped() const { return code_range(type).has_value(); }

double RawEncoding::code(double v) const { return is_mapped() ? first + (v - min) * scale : v; }

RawEncoding raw_encoding(const Volume& volume, ScalarType type) {
  RawEncoding e;
  e.type = type;
  if (volume.size() > 0) {
    const auto [lo, hi] = std::minmax_element(volume.data(), volume.data() + volume.size());
    e.min = *lo;
    e.max = *hi;
  }
  if (const auto range = code_range(type)) {
    e.first = range->lo;
    e.scale = e.max > e.min ? (range->hi - range->lo) / (e.max - e.min) : 0.0;
  }
  return e;
}

RawEncoding write_raw(const Volume& volume, const std::string& path, ScalarType type) {
  const int bytes = scalar_type_size(type);
  check_shape(volume, path, bytes);
  // A NaN has no code; float types pass values through as they are.
  if (code_range(type)) check_finite(volume, path);
  const RawEncoding e = raw_encoding(volume, type);
  AtomicFile out(path);
  constexpr size_t kBlock = size_t{1} << 16;
  std::vector<unsigned char> buffer(kBlock * static_cast<size_t>(bytes));
  const std::span<const float> values(volume.data(), volume.size());
  for (size_t i = 0; i < values.size(); i += kBlock) {
    const std::span<const float> block = values.subspan(i, std::min(kBlock, values.size() - i));
    encode_block(e, block, buffer.data());
    out.write(buffer.data(), block.size() * static_cast<size_t>(bytes));
  }
  out.commit();
  return e;
}

void write_hdf5(const Volume& volume, const std::string& path) {
  check_shape(volume, path, static_cast<int>(sizeof(float)));
  silence_hdf5_errors();
  // AtomicFile reserves a unique temporary beside PATH and removes it on any failure;
  // HDF5 writes that same path through its own descriptor, and commit() fsyncs and renames it.
  AtomicFile out(path);
  Hdf5Handle file(H5Fcreate(out.temp_path().c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT), H5Fclose);
  if (!file) throw IoError(path + ": cannot create HDF5 file: " + hdf5_error_detail());
  write_volume_dataset(file.get(), volume, path);
  if (!file.close()) throw IoError(path + ": cannot finish HDF5 file: " + hdf5_error_detail());
  out.commit();
}

}  // namespace isotope
