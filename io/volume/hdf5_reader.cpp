#include "io/volume/hdf5_reader.h"

#include <fcntl.h>
#include <hdf5.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <mutex>
#include <new>

#include "engine/core/huge_blocks.h"
#include "io/file/input_file.h"
#include "io/volume/box_reader.h"
#include "io/volume/hdf5_handle.h"
#include "io/volume/raw_data_reader.h"
#include "io/volume/raw_reader.h"
#include "isotope/error.h"

namespace isotope {
namespace {

namespace fs = std::filesystem;

std::string join(const std::vector<std::string>& items) {
  std::string out;
  for (const auto& s : items) out += (out.empty() ? "" : ", ") + s;
  return out;
}

bool is_numeric(hid_t dataset) {
  const Hdf5Handle type(H5Dget_type(dataset), H5Tclose);
  if (!type) return false;
  const H5T_class_t cls = H5Tget_class(type.get());
  return cls == H5T_INTEGER || cls == H5T_FLOAT;
}

int rank_of(hid_t dataset) {
  const Hdf5Handle space(H5Dget_space(dataset), H5Sclose);
  return space ? H5Sget_simple_extent_ndims(space.get()) : -1;
}

#if H5_VERSION_GE(1, 12, 0)
using ObjectInfo = H5O_info2_t;
#else
using ObjectInfo = H5O_info_t;
#endif

// Called from C: an exception must not cross it, so allocation failure stops the visit instead.
herr_t collect_3d(hid_t root, const char* name, const ObjectInfo* info, void* out) noexcept {
  if (info->type != H5O_TYPE_DATASET) return 0;
  const Hdf5Handle ds(H5Dopen2(root, name, H5P_DEFAULT), H5Dclose);
  if (!ds || rank_of(ds.get()) != 3 || !is_numeric(ds.get())) return 0;
  try {
    static_cast<std::vector<std::string>*>(out)->push_back("/" + std::string(name));
  } catch (...) {
    return -1;
  }
  return 0;
}

std::vector<std::string> datasets_3d(hid_t file_id, const std::string& file) {
  std::vector<std::string> names;
#if H5_VERSION_GE(1, 12, 0)
  const herr_t rc = H5Ovisit3(file_id, H5_INDEX_NAME, H5_ITER_INC, collect_3d, &names, H5O_INFO_BASIC);
#else
  const herr_t rc = H5Ovisit2(file_id, H5_INDEX_NAME, H5_ITER_INC, collect_3d, &names, H5O_INFO_BASIC);
#endif
  if (rc < 0) throw IoError(file + ": cannot list datasets: " + hdf5_error_detail());
  std::sort(names.begin(), names.end());
  return names;
}

// Reads a 3-number attribute (x, y, z) when present; absent leaves VALUE untouched.
void read_xyz_attribute(hid_t ds, const char* name, const std::string& where, bool positive,
                        std::array<double, 3>& value) {
  const htri_t exists = H5Aexists(ds, name);
  if (exists < 0) throw IoError(where + ": cannot query attribute '" + name + "'");
  if (exists == 0) return;
  const std::string bad = where + ": attribute '" + name + "' ";
  const Hdf5Handle attr(H5Aopen(ds, name, H5P_DEFAULT), H5Aclose);
  if (!attr) throw IoError(bad + "cannot be opened: " + hdf5_error_detail());
  const Hdf5Handle type(H5Aget_type(attr.get()), H5Tclose);
  const Hdf5Handle space(H5Aget_space(attr.get()), H5Sclose);
  if (!type || !space) throw IoError(bad + "cannot be inspected: " + hdf5_error_detail());
  const H5T_class_t cls = H5Tget_class(type.get());
  if ((cls != H5T_INTEGER && cls != H5T_FLOAT) || H5Sget_simple_extent_npoints(space.get()) != 3)
    throw IoError(bad + "must hold 3 numbers (x, y, z)");
  std::array<double, 3> v{};
  if (H5Aread(attr.get(), H5T_NATIVE_DOUBLE, v.data()) < 0)
    throw IoError(bad + "cannot be read: " + hdf5_error_detail());
  for (double c : v) {
    if (!std::isfinite(c) || (positive && c <= 0))
      throw IoError(bad + (positive ? "must be finite and > 0" : "must be finite"));
  }
  value = v;
}

}  // namespace

Hdf5Handle open_hdf5_file(const std::string& file) {
  silence_hdf5_errors();
  require_regular_file(file, file, "an HDF5 file");
  const htri_t is_hdf5 = H5Fis_hdf5(file.c_str());
  if (is_hdf5 == 0) throw IoError(file + ": not an HDF5 file");
  if (is_hdf5 < 0) throw IoError(file + ": cannot open: " + hdf5_error_detail());
  Hdf5Handle f(H5Fopen(file.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT), H5Fclose);
  if (!f) throw IoError(file + ": cannot open HDF5 file: " + hdf5_error_detail());
  return f;
}

Hdf5Handle open_hdf5_dataset(hid_t file_id, const std::string& file, const std::string& dataset) {
  // H5Lexists fails on a missing intermediate group, so a failed open is the test.
  Hdf5Handle ds(H5Dopen2(file_id, dataset.c_str(), H5P_DEFAULT), H5Dclose);
  if (ds) return ds;
  const auto found = datasets_3d(file_id, file);
  throw IoError(file + ": no dataset '" + dataset +
                "'; 3-D datasets in the file: " + (found.empty() ? "none" : join(found)));
}

std::array<int64_t, 3> hdf5_dataset_dims(hid_t ds, const std::string& where) {
  if (!is_numeric(ds)) throw IoError(where + ": type is not numeric (need integer or float)");
  const Hdf5Handle space(H5Dget_space(ds), H5Sclose);
  if (!space) throw IoError(where + ": cannot read dataspace: " + hdf5_error_detail());
  const int rank = H5Sget_simple_extent_ndims(space.get());
  if (rank != 3) throw IoError(where + ": rank " + std::to_string(rank) + ", expected 3 (z, y, x)");
  hsize_t zyx[3] = {0, 0, 0};
  if (H5Sget_simple_extent_dims(space.get(), zyx, nullptr) < 0)
    throw IoError(where + ": cannot read dimensions: " + hdf5_error_detail());
  for (hsize_t d : zyx) {
    if (d > static_cast<hsize_t>(INT64_MAX)) throw IoError(where + ": dimensions too large");
  }
  return {static_cast<int64_t>(zyx[2]), static_cast<int64_t>(zyx[1]), static_cast<int64_t>(zyx[0])};
}

void read_hdf5_geometry(hid_t ds, const std::string& where, std::array<double, 3>& spacing,
                        std::array<double, 3>& origin) {
  read_xyz_attribute(ds, "spacing", where, true, spacing);
  read_xyz_attribute(ds, "origin", where, false, origin);
}

std::vector<std::string> list_3d_datasets(const std::string& file) {
  const std::lock_guard lock(hdf5_mutex());  // declared first, so released after the handles close
  const Hdf5Handle f = open_hdf5_file(file);
  return datasets_3d(f.get(), file);
}

Volume read_hdf5(const std::string& file, const std::string& dataset) {
  const std::lock_guard lock(hdf5_mutex());
  const Hdf5Handle f = open_hdf5_file(file);
  const Hdf5Handle ds = open_hdf5_dataset(f.get(), file, dataset);
  const std::string where = file + ":" + dataset;
  Volume volume;
  volume.dims = hdf5_dataset_dims(ds.get(), where);
  const int64_t count = checked_node_count(volume.dims, static_cast<int>(sizeof(float)), where);
  read_hdf5_geometry(ds.get(), where, volume.spacing, volume.origin);
  try {
    detail::resize_prefaulted_in_parallel(volume.values, static_cast<size_t>(count));
  } catch (const std::bad_alloc&) {
    throw IoError(where + ": volume does not fit in memory");
  }
  // HDF5 converts any integer or float file type to float and undoes chunking and filters.
  if (H5Dread(ds.get(), H5T_NATIVE_FLOAT, H5S_ALL, H5S_ALL, H5P_DEFAULT, volume.values.data()) < 0)
    throw IoError(where + ": cannot read data: " + hdf5_error_detail());
  check_finite(volume, where);
  return volume;
}

// ---------------------------------------------------------------- by boxes

namespace {

// A dataset that is not raw data at an offset (contiguous_hdf5_data, below): HDF5 selects the box
// as a hyperslab and converts to float (or reads small integers as they are) itself, undoing
// chunking and filters; every call holds hdf5_mutex(), so concurrent boxes are read one after the
// other.
class Hdf5BoxReader final : public BoxReader {
 public:
  Hdf5BoxReader(Hdf5Handle file, Hdf5Handle dataset, std::string where, const VolumeInfo& info)
      : file_(std::move(file)), dataset_(std::move(dataset)), where_(std::move(where)) {
    info_ = info;
  }
  ~Hdf5BoxReader() override {
    const std::lock_guard lock(hdf5_mutex());
    dataset_.close();
    file_.close();
  }
  Hdf5BoxReader(const Hdf5BoxReader&) = delete;
  Hdf5BoxReader& operator=(const Hdf5BoxReader&) = delete;

  void read_box(const std::array<int64_t, 3>& lo, const std::array<int64_t, 3>& size, float* out) const override {
    read_box_unchecked(lo, size, out);
    if (!info_.is_integer) check_finite(out, lo, size, where_);  // an integer is finite as float
  }

  void read_box_unchecked(const std::array<int64_t, 3>& lo, const std::array<int64_t, 3>& size,
                          float* out) const override {
    check_box(lo, size, info_, where_);
    if (size[0] * size[1] * size[2] == 0) return;
    read_hyperslab(lo, size, std::nullopt, out);
  }

  // Integers of one or two bytes, in this machine's byte order (HDF5 swaps a big-endian file's).
  // Converting them to float is HDF5's slowest path: one value at a time, on one thread, through a
  // buffer of its own, which the one-shot march at eps 0 (the raw file's path) need not take.
  std::optional<ScalarType> stored_type() const override {
    const std::optional<ScalarType> t = parse_scalar_type(info_.type);
    if (t == ScalarType::uint8 || t == ScalarType::uint16 || t == ScalarType::int16) return t;
    return std::nullopt;
  }

  void read_box_stored(const std::array<int64_t, 3>& lo, const std::array<int64_t, 3>& size,
                       unsigned char* out) const override {
    const std::optional<ScalarType> type = stored_type();
    if (!type) throw std::logic_error(where_ + ": values cannot be read as stored");
    check_box(lo, size, info_, where_);
    if (size[0] * size[1] * size[2] == 0) return;
    read_hyperslab(lo, size, type, out);
  }

 private:
  // The box as floats, or as STORED values, into OUT: HDF5 converts from the file's type.
  void read_hyperslab(const std::array<int64_t, 3>& lo, const std::array<int64_t, 3>& size,
                      std::optional<ScalarType> stored, void* out) const {
    const hsize_t start[3] = {static_cast<hsize_t>(lo[2]), static_cast<hsize_t>(lo[1]), static_cast<hsize_t>(lo[0])};
    const hsize_t count[3] = {static_cast<hsize_t>(size[2]), static_cast<hsize_t>(size[1]),
                              static_cast<hsize_t>(size[0])};
    const std::lock_guard lock(hdf5_mutex());  // declared first, so released after the handles close
    const Hdf5Handle file_space(H5Dget_space(dataset_.get()), H5Sclose);
    const Hdf5Handle memory_space(H5Screate_simple(3, count, nullptr), H5Sclose);
    const std::string box = " box of size " + coordinates_text(size) + " at (x,y,z) = " + coordinates_text(lo);
    if (!file_space || !memory_space ||
        H5Sselect_hyperslab(file_space.get(), H5S_SELECT_SET, start, nullptr, count, nullptr) < 0)
      throw IoError(where_ + ": cannot select the" + box + ": " + hdf5_error_detail());
    // H5T_NATIVE_* call into the library (they open it on first use): under the lock too.
    const hid_t memory_type = !stored                         ? H5T_NATIVE_FLOAT
                              : *stored == ScalarType::uint8  ? H5T_NATIVE_UINT8
                              : *stored == ScalarType::uint16 ? H5T_NATIVE_UINT16
                                                              : H5T_NATIVE_INT16;
    if (H5Dread(dataset_.get(), memory_type, memory_space.get(), file_space.get(), H5P_DEFAULT, out) < 0)
      throw IoError(where_ + ": cannot read the" + box + ": " + hdf5_error_detail());
  }

  Hdf5Handle file_;
  Hdf5Handle dataset_;
  std::string where_;
};

// "uint16", "int32", "float64", ...: the dataset's type as stored. The caller holds hdf5_mutex().
void set_hdf5_type(hid_t dataset, const std::string& where, VolumeInfo& info) {
  const Hdf5Handle type(H5Dget_type(dataset), H5Tclose);
  if (!type) throw IoError(where + ": cannot read the type: " + hdf5_error_detail());
  info.is_integer = H5Tget_class(type.get()) == H5T_INTEGER;
  info.element_bytes = static_cast<int>(H5Tget_size(type.get()));
  const bool is_unsigned = info.is_integer && H5Tget_sign(type.get()) == H5T_SGN_NONE;
  info.type =
      std::string(info.is_integer ? (is_unsigned ? "uint" : "int") : "float") + std::to_string(8 * info.element_bytes);
}

// Boxes cut a chunked dataset's chunks (the one-shot march's windows of z-layers), and HDF5 keeps
// 1 MB of decoded chunks by default: a chunk deeper than a window was read and inflated again for
// every window that cut it (docs/METHOD.md, "eps = 0 from a file"). DS is opened again with a
// cache that holds one layer of chunks across the plane, where that takes more than the default
// and at most CACHE_BYTES; a chunk read wholly goes first (w0 = 1). The caller holds
// hdf5_mutex().
Hdf5Handle with_chunk_cache(hid_t file, const std::string& dataset, const std::string& where, Hdf5Handle ds,
                            const VolumeInfo& info, uint64_t cache_bytes) {
  constexpr double kDefaultBytes = 1 << 20;
  const Hdf5Handle create(H5Dget_create_plist(ds.get()), H5Pclose);
  hsize_t zyx[3] = {0, 0, 0};
  if (!create || H5Pget_layout(create.get()) != H5D_CHUNKED || H5Pget_chunk(create.get(), 3, zyx) != 3 ||
      zyx[0] * zyx[1] * zyx[2] == 0)
    return ds;
  const auto chunks_along = [](int64_t nodes, hsize_t chunk) {
    return std::ceil(static_cast<double>(nodes) / static_cast<double>(chunk));
  };
  const double chunk_bytes =
      static_cast<double>(zyx[0]) * static_cast<double>(zyx[1]) * static_cast<double>(zyx[2]) * info.element_bytes;
  const double chunks = chunks_along(info.dims[1], zyx[1]) * chunks_along(info.dims[0], zyx[2]);
  const double layer = chunk_bytes * chunks;
  if (layer <= kDefaultBytes || layer > static_cast<double>(cache_bytes)) return ds;
  // HDF5's guide: slots a prime number about 100 times the chunks the cache holds; a pointer each,
  // allocated at open, so at most 2^18 of them (a hash table of tiny chunks only collides more).
  auto slots = static_cast<size_t>(std::min(100 * chunks, double{1 << 18})) | 1;
  const auto prime = [](size_t n) {
    for (size_t d = 3; d * d <= n; d += 2)
      if (n % d == 0) return false;
    return true;
  };
  while (!prime(slots)) slots += 2;
  const Hdf5Handle access(H5Pcreate(H5P_DATASET_ACCESS), H5Pclose);
  if (!access || H5Pset_chunk_cache(access.get(), slots, static_cast<size_t>(layer), 1.0) < 0) return ds;
  // The cache is the open dataset's: another handle to it while it is open would share its cache.
  ds.close();
  Hdf5Handle again(H5Dopen2(file, dataset.c_str(), access.get()), H5Dclose);
  if (!again) throw IoError(where + ": cannot open it again with a chunk cache: " + hdf5_error_detail());
  VolumeInfo now;  // the same path may have come to name another dataset since
  now.dims = hdf5_dataset_dims(again.get(), where);
  set_hdf5_type(again.get(), where, now);
  if (now.dims != info.dims || now.type != info.type)
    throw IoError(where + ": the dataset changed while it was opened");
  return again;
}

// The values of a dataset stored contiguously, unfiltered and whole in the file HDF5 opened, in a
// type raw data has: where they start, their type and byte order. Such a dataset is raw data at an
// offset, read without the library, its lock or a stage, on every thread at once (docs/METHOD.md,
// "HDF5 datasets"). Anything else (chunks, a compact dataset, external files, space never written,
// other types, another file driver) is left to HDF5, and its messages. The end of file it checks
// against is the one HDF5 knows (which H5Fopen has held the file to). The caller holds
// hdf5_mutex().
std::optional<RawData> contiguous_hdf5_data(hid_t file, hid_t dataset, const VolumeInfo& info) {
  const Hdf5Handle create(H5Dget_create_plist(dataset), H5Pclose);
  if (!create || H5Pget_layout(create.get()) != H5D_CONTIGUOUS || H5Pget_external_count(create.get()) != 0)
    return std::nullopt;
  H5D_space_status_t status{};
  if (H5Dget_space_status(dataset, &status) < 0 || status != H5D_SPACE_STATUS_ALLOCATED) return std::nullopt;
  const uint64_t bytes =
      static_cast<uint64_t>(info.dims[0] * info.dims[1] * info.dims[2]) * static_cast<uint64_t>(info.element_bytes);
  const haddr_t offset = H5Dget_offset(dataset);
  hsize_t file_bytes = 0;
  if (offset == HADDR_UNDEF || H5Dget_storage_size(dataset) != bytes || H5Fget_filesize(file, &file_bytes) < 0 ||
      offset > file_bytes || file_bytes - offset < bytes)
    return std::nullopt;
  const Hdf5Handle type(H5Dget_type(dataset), H5Tclose);
  if (!type) return std::nullopt;
  struct Known {
    hid_t little, big;
    ScalarType as;
  };
  const Known known[] = {{H5T_STD_U8LE, H5T_STD_U8BE, ScalarType::uint8},
                         {H5T_STD_U16LE, H5T_STD_U16BE, ScalarType::uint16},
                         {H5T_STD_I16LE, H5T_STD_I16BE, ScalarType::int16},
                         {H5T_IEEE_F32LE, H5T_IEEE_F32BE, ScalarType::float32},
                         {H5T_IEEE_F64LE, H5T_IEEE_F64BE, ScalarType::float64}};
  for (const Known& k : known) {
    for (const bool big : {false, true})
      if (H5Tequal(type.get(), big ? k.big : k.little) > 0)
        return RawData{static_cast<int64_t>(offset), k.as, big, {}, {}};
  }
  return std::nullopt;
}

// The descriptor HDF5 read FILE through, duplicated: the file whose layout it read, whatever its
// path names now. -1 where the driver holds none. The caller holds hdf5_mutex().
int duplicate_hdf5_descriptor(hid_t file) {
  const Hdf5Handle access(H5Fget_access_plist(file), H5Pclose);
  if (!access || H5Pget_driver(access.get()) != H5FD_SEC2) return -1;  // whose handle is a descriptor
  void* handle = nullptr;
  if (H5Fget_vfd_handle(file, H5P_DEFAULT, &handle) < 0 || handle == nullptr) return -1;
  return ::fcntl(*static_cast<int*>(handle), F_DUPFD_CLOEXEC, 0);
}

}  // namespace

std::unique_ptr<BoxReader> open_hdf5_box_reader(const std::string& file, const std::string& dataset,
                                                uint64_t chunk_cache_bytes) {
  const std::lock_guard lock(hdf5_mutex());  // declared first, so released after the handles close
  Hdf5Handle f = open_hdf5_file(file);
  Hdf5Handle ds = open_hdf5_dataset(f.get(), file, dataset);
  const std::string where = file + ":" + dataset;
  VolumeInfo info;
  info.dims = hdf5_dataset_dims(ds.get(), where);  // also checks the type is numeric
  checked_node_count(info.dims, static_cast<int>(sizeof(float)), where);
  read_hdf5_geometry(ds.get(), where, info.spacing, info.origin);
  set_hdf5_type(ds.get(), where, info);
  if (std::optional<RawData> raw = contiguous_hdf5_data(f.get(), ds.get(), info)) {
    FileDescriptor fd(duplicate_hdf5_descriptor(f.get()));
    if (fd.get() >= 0) {
      raw->name = where;
      raw->read_name = file;
      return open_raw_data(std::move(fd), std::move(*raw), info);
    }
  }
  Hdf5Handle cached = with_chunk_cache(f.get(), dataset, where, std::move(ds), info, chunk_cache_bytes);
  return std::make_unique<Hdf5BoxReader>(std::move(f), std::move(cached), where, info);
}

}  // namespace isotope
