#pragma once
// Raw values at a byte offset of one file, read by boxes: the box reader of a raw file, of a raw
// or inflated NRRD's data and of a contiguous HDF5 dataset.
#include <bit>
#include <cstdint>
#include <memory>
#include <string>

#include "io/file/input_file.h"
#include "io/volume/box_reader.h"
#include "isotope/volume.h"

namespace isotope {

struct RawData {
  int64_t offset = 0;  // byte of node (0, 0, 0)
  ScalarType type = ScalarType::uint8;
  bool big_endian = false;
  std::string name;       // how messages name the volume
  std::string read_name;  // how read errors name the file read (an inflated copy differs)
  // Whether values of more than a byte are in the other byte order than this machine's.
  bool swapped() const { return big_endian != (std::endian::native == std::endian::big); }
};

// A reader of DATA in FD, which it reads with pread: from any thread, with no lock. KEEP lives as
// long as the reader: what FD reads where that must go with the reader (an inflated copy).
std::unique_ptr<BoxReader> open_raw_data(FileDescriptor fd, RawData data, const VolumeInfo& info,
                                         std::shared_ptr<const void> keep = nullptr);

}  // namespace isotope
