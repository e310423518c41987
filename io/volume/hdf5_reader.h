#pragma once
// One 3-D dataset of an HDF5 file, any integer or float type, C order (z, y, x): x fastest.
// Attributes "spacing" and "origin" (3 values, x y z) are used when present.
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "isotope/volume.h"

namespace isotope {

// Throws IoError: missing file, not HDF5, missing dataset, rank != 3, non-numeric type, NaN.
Volume read_hdf5(const std::string& file, const std::string& dataset);

// Paths ("/a/b") of the rank-3 numeric datasets in FILE, sorted. Throws IoError: missing file, not HDF5.
std::vector<std::string> list_3d_datasets(const std::string& file);

class BoxReader;
// A dataset read by boxes (BoxReader): one stored whole and contiguous, as raw data at
// its offset, on every thread at once; any other through HDF5, keeping up to CHUNK_CACHE_BYTES of
// decoded chunks (0: HDF5's default).
std::unique_ptr<BoxReader> open_hdf5_box_reader(const std::string& file, const std::string& dataset,
                                                uint64_t chunk_cache_bytes);

}  // namespace isotope
