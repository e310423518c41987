#include "io/volume/hdf5_reader.h"

#include <hdf5.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <mutex>
#include <new>

#include "io/file/input_file.h"
#include "io/volume/hdf5_handle.h"
#include "io/volume/raw_reader.h"
#include "isotope/detail/huge_page_allocator.h"
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

}  // namespace isotope
