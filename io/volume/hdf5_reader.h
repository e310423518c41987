#pragma once
// One 3-D dataset of an HDF5 file, any integer or float type, C order (z, y, x): x fastest.
// Attributes "spacing" and "origin" (3 values, x y z) are used when present.
#include <string>
#include <vector>

#include "isotope/volume.h"

namespace isotope {

// Throws IoError: missing file, not HDF5, missing dataset, rank != 3, non-numeric type, NaN.
Volume read_hdf5(const std::string& file, const std::string& dataset);

// Paths ("/a/b") of the rank-3 numeric datasets in FILE, sorted. Throws IoError: missing file, not HDF5.
std::vector<std::string> list_3d_datasets(const std::string& file);

}  // namespace isotope
