#include "io/volume_writer.h"

#include <algorithm>
#include <bit>
#include <cstdint>
#include <vector>

#include "io/atomic_file.h"
#include "io/hdf5_handle.h"
#include "io/io_error.h"
#include "io/raw_reader.h"

namespace isotope {
namespace {

void check_shape(const Volume& volume, const std::string& path) {
  const int64_t count = checked_node_count(volume.dims, static_cast<int>(sizeof(float)), path);
  if (static_cast<int64_t>(volume.values.size()) != count) {
    throw IoError(path + ": volume holds " + std::to_string(volume.values.size()) +
                  " values but its dimensions need " + std::to_string(count));
  }
}

uint32_t byteswap32(uint32_t b) {
  return (b >> 24) | ((b >> 8) & 0xff00u) | ((b << 8) & 0xff0000u) | (b << 24);
}

void write_floats_le(AtomicFile& out, const std::vector<float>& values) {
  if constexpr (std::endian::native == std::endian::little) {
    out.write(values.data(), values.size() * sizeof(float));
  } else {
    constexpr size_t kBlock = size_t{1} << 18;
    std::vector<uint32_t> buffer;
    for (size_t i = 0; i < values.size(); i += kBlock) {
      const size_t n = std::min(kBlock, values.size() - i);
      buffer.resize(n);
      for (size_t k = 0; k < n; ++k) buffer[k] = byteswap32(std::bit_cast<uint32_t>(values[i + k]));
      out.write(buffer.data(), n * sizeof(uint32_t));
    }
  }
}

void write_xyz_attribute(hid_t ds, const char* name, const std::array<double, 3>& v,
                         const std::string& path) {
  const hsize_t three = 3;
  const Hdf5Handle space(H5Screate_simple(1, &three, nullptr), H5Sclose);
  const Hdf5Handle attr(space ? H5Acreate2(ds, name, H5T_IEEE_F64LE, space.get(), H5P_DEFAULT, H5P_DEFAULT)
                              : H5I_INVALID_HID,
                        H5Aclose);
  if (!attr || H5Awrite(attr.get(), H5T_NATIVE_DOUBLE, v.data()) < 0)
    throw IoError(path + ": cannot write attribute '" + name + "': " + hdf5_error_detail());
}

void write_volume_dataset(hid_t file, const Volume& volume, const std::string& path) {
  const hsize_t zyx[3] = {static_cast<hsize_t>(volume.dims[2]), static_cast<hsize_t>(volume.dims[1]),
                          static_cast<hsize_t>(volume.dims[0])};
  const Hdf5Handle space(H5Screate_simple(3, zyx, nullptr), H5Sclose);
  const Hdf5Handle ds(space ? H5Dcreate2(file, "/volume", H5T_IEEE_F32LE, space.get(), H5P_DEFAULT,
                                         H5P_DEFAULT, H5P_DEFAULT)
                            : H5I_INVALID_HID,
                      H5Dclose);
  if (!ds) throw IoError(path + ": cannot create dataset /volume: " + hdf5_error_detail());
  if (H5Dwrite(ds.get(), H5T_NATIVE_FLOAT, H5S_ALL, H5S_ALL, H5P_DEFAULT, volume.values.data()) < 0)
    throw IoError(path + ": cannot write dataset /volume: " + hdf5_error_detail());
  write_xyz_attribute(ds.get(), "spacing", volume.spacing, path);
  write_xyz_attribute(ds.get(), "origin", volume.origin, path);
}

}  // namespace

void write_raw_float32(const Volume& volume, const std::string& path) {
  check_shape(volume, path);
  AtomicFile out(path);
  write_floats_le(out, volume.values);
  out.commit();
}

void write_hdf5(const Volume& volume, const std::string& path) {
  check_shape(volume, path);
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
