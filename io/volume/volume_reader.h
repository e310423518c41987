#pragma once
// Opens what a user names on the command line: "vol.raw", "vol.nrrd", "file.h5:/path/to/dataset", or a
// TIFF stack ("scan.tif", a multi-page file, or "slices/", a folder of one file per slice).
#include <optional>
#include <string>

#include "io/volume/raw_reader.h"
#include "isotope/source.h"  // VolumeSpec
#include "isotope/volume.h"

namespace isotope {

// Throws IoError with a message naming the file and what is wrong.
Volume read_volume(const VolumeSpec& source);

// Where a source's values are, decided from the spec and the overrides without reading them.
struct VolumeLocation {
  enum class Format { raw, hdf5, nrrd, tiff };
  Format format = Format::raw;
  std::string file;
  std::string dataset;  // hdf5: the dataset, found in the file when the spec names none
  RawLayout layout;     // raw: dims and type from the overrides or the file name
};

// What read_volume reads. Throws IoError as read_volume does when the spec names no readable
// volume (missing file, raw layout unknown, HDF5 file without exactly one 3-D dataset).
VolumeLocation locate_volume(const VolumeSpec& source);

}  // namespace isotope
