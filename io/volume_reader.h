#pragma once
// Opens what a user names on the command line: "vol.raw" or "file.h5:/path/to/dataset".
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

}  // namespace isotope
