#pragma once
// Opens what a user names on the command line: "vol.raw", "vol.nrrd" or "file.h5:/path/to/dataset".
#include <optional>
#include <string>

#include "engine/volume.h"
#include "io/raw_reader.h"

namespace isotope {

struct VolumeSource {
  std::string spec;                      // path, or FILE.h5:/dataset
  std::optional<std::array<int64_t, 3>> dims;   // raw only: overrides the file name
  std::optional<ScalarType> type;               // raw only: overrides the file name
};

// Throws IoError with a message naming the file and what is wrong.
Volume read_volume(const VolumeSource& source);

// Where a source's values are, decided from the spec and the overrides without reading them.
struct VolumeLocation {
  enum class Format { raw, hdf5, nrrd };
  Format format = Format::raw;
  std::string file;
  std::string dataset;  // hdf5: the dataset, found in the file when the spec names none
  RawLayout layout;     // raw: dims and type from the overrides or the file name
};

// What read_volume reads. Throws IoError as read_volume does when the spec names no readable
// volume (missing file, raw layout unknown, HDF5 file without exactly one 3-D dataset).
VolumeLocation locate_volume(const VolumeSource& source);

}  // namespace isotope
