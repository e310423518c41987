#pragma once
// NRRD volumes (magic NRRD0001..NRRD0005, http://teem.sourceforge.net/nrrd/format.html):
// a .nrrd with the data attached after its header, or a .nhdr naming a detached "data file".
// Read: 3-D, uchar/short/ushort/float/double, raw or gzip, either endian; first axis fastest.
#include <array>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>

#include "io/volume/raw_reader.h"
#include "isotope/volume.h"

namespace isotope {

enum class NrrdEncoding { raw, gzip };

// Where and how a header says its values are stored, checked against the data file's size.
struct NrrdLayout {
  std::string data_path;      // the header itself (attached) or the detached data file
  std::string where;          // how messages name the data: PATH, or "PATH: data file DATA"
  int64_t data_offset = 0;    // raw: first value; gzip: first compressed byte
  int64_t inflated_skip = 0;  // gzip: decompressed bytes before the first value
  NrrdEncoding encoding = NrrdEncoding::raw;
  ScalarType type = ScalarType::uint8;
  bool big_endian = false;
  std::array<int64_t, 3> dims{0, 0, 0};
  std::array<double, 3> spacing{1, 1, 1};
  std::array<double, 3> origin{0, 0, 0};

  int64_t data_bytes() const { return dims[0] * dims[1] * dims[2] * scalar_type_size(type); }
};

// Spacing comes from "spacings" or the lengths of "space directions", origin from
// "space origin"; both default as in Volume. Throws IoError naming PATH: not NRRD, dimension
// other than 3, unsupported type or encoding, missing field, missing or truncated data,
// corrupt gzip stream, NaN or infinite values.
Volume read_nrrd(const std::string& path);

// Parses and checks the header and the data file's size without reading any value. Throws
// IoError naming PATH as read_nrrd does.
NrrdLayout read_nrrd_layout(const std::string& path);

// Hands the data bytes, as stored (not byteswapped), to SINK in order, in blocks of at most
// 1 MiB that each hold whole values; gzip data are inflated on the way. Throws IoError naming
// layout.where: missing or truncated data, corrupt gzip stream, more gzip data than the header says.
using NrrdBlockSink = std::function<void(const unsigned char* bytes, size_t size)>;
void stream_nrrd_data(const NrrdLayout& layout, const NrrdBlockSink& sink);

class BoxReader;
// A NRRD read by boxes (BoxReader): raw data in place; gzip data inflated once,
// streaming, into a scratch file in SCRATCH_DIR that goes with the reader.
std::unique_ptr<BoxReader> open_nrrd_box_reader(const std::string& path, const std::string& scratch_dir);

}  // namespace isotope
