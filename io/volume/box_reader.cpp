#include "io/volume/box_reader.h"

#include <stdexcept>

#include "io/volume/hdf5_reader.h"
#include "io/volume/nrrd_reader.h"
#include "io/volume/raw_reader.h"
#include "io/volume/tiff_reader.h"
#include "isotope/error.h"

namespace isotope {

VolumeInfo volume_info(ScalarType type, const std::array<int64_t, 3>& dims, const std::array<double, 3>& spacing,
                       const std::array<double, 3>& origin) {
  VolumeInfo info;
  info.dims = dims;
  info.spacing = spacing;
  info.origin = origin;
  info.type = scalar_type_name(type);
  info.element_bytes = scalar_type_size(type);
  info.is_integer = type != ScalarType::float32 && type != ScalarType::float64;
  return info;
}

std::string coordinates_text(const std::array<int64_t, 3>& v) {
  return "(" + std::to_string(v[0]) + "," + std::to_string(v[1]) + "," + std::to_string(v[2]) + ")";
}

// A size of 0 is inside (it reads nothing). lo + size is never formed, so it cannot overflow.
void check_box(const std::array<int64_t, 3>& lo, const std::array<int64_t, 3>& size, const VolumeInfo& info,
               const std::string& where) {
  for (int axis = 0; axis < 3; ++axis) {
    if (lo[axis] < 0 || size[axis] < 0 || size[axis] > info.dims[axis] - lo[axis]) {
      throw InvalidInput(where + ": box of size " + coordinates_text(size) + " at (x,y,z) = " + coordinates_text(lo) +
                         " is not inside the volume of size " + coordinates_text(info.dims));
    }
  }
}

std::unique_ptr<BoxReader> open_box_reader(const VolumeSpec& source, const std::string& scratch_dir,
                                           uint64_t hdf5_chunk_cache_bytes) {
  const VolumeLocation at = locate_volume(source);
  std::unique_ptr<BoxReader> reader;
  switch (at.format) {
    case VolumeLocation::Format::hdf5:
      reader = open_hdf5_box_reader(at.file, at.dataset, hdf5_chunk_cache_bytes);
      break;
    case VolumeLocation::Format::nrrd: reader = open_nrrd_box_reader(at.file, scratch_dir); break;
    case VolumeLocation::Format::tiff: reader = open_tiff_stack(at.file); break;
    case VolumeLocation::Format::raw: reader = open_raw_box_reader(at.file, at.layout); break;
  }
  const VolumeInfo& info = reader->info();
  check_volume_layout(info.dims, info.spacing, info.origin, at.file);
  return reader;
}

}  // namespace isotope
