#pragma once
// Writes generated volumes: float32 raw (x fastest) or an HDF5 dataset "/volume" of shape (z, y, x).
#include <string>

#include "engine/volume.h"

namespace isotope {

void write_raw_float32(const Volume& volume, const std::string& path);   // atomic; throws IoError
void write_hdf5(const Volume& volume, const std::string& path);          // atomic; throws IoError

}  // namespace isotope
