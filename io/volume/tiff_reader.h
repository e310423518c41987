#pragma once
// TIFF stacks, the usual form of micro-CT data: a multi-page TIFF (page k is slice z = k) or a
// folder of single-page TIFF files (one slice each, in the natural order of their names, so that
// slice_2.tif comes before slice_10.tif). One channel per pixel, stored as uint8, uint16, int16,
// float32 or float64, in strips or tiles, with any compression libtiff decodes.
#include <memory>
#include <string>

#include "io/volume/box_reader.h"

namespace isotope {

// True when PATH names a folder or a file ending in .tif or .tiff (case-insensitive).
bool is_tiff_stack(const std::string& path);

// Checks every page at open (size, channels, element type, the same throughout) without decoding
// any; read_box then decodes only the strips or tiles a box touches, with a libtiff handle of its
// own, so that concurrent boxes need no lock. Throws IoError naming the file (and page) and what
// is wrong; libtiff's own words are kept in the message, and it prints nothing.
std::unique_ptr<BoxReader> open_tiff_stack(const std::string& path);
// The whole stack, as read_volume reads every format. Throws IoError as above.
Volume read_tiff_stack(const std::string& path);

}  // namespace isotope
