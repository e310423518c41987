#pragma once
// NRRD volumes (magic NRRD0001..NRRD0005, http://teem.sourceforge.net/nrrd/format.html):
// a .nrrd with the data attached after its header, or a .nhdr naming a detached "data file".
// Read: 3-D, uchar/short/ushort/float/double, raw or gzip, either endian; first axis fastest.
#include <string>

#include "engine/volume.h"

namespace isotope {

// Spacing comes from "spacings" or the lengths of "space directions", origin from
// "space origin"; both default as in Volume. Throws IoError naming PATH: not NRRD, dimension
// other than 3, unsupported type or encoding, missing field, missing or truncated data,
// corrupt gzip stream, NaN or infinite values.
Volume read_nrrd(const std::string& path);

}  // namespace isotope
