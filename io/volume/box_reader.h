#pragma once
// Random access to sub-boxes of a volume on disk, for volumes larger than memory: a reader is
// opened once and then asked for many boxes (a tile plus its halo), from several threads.
#include <array>
#include <cstdint>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>

#include "io/volume/volume_reader.h"

namespace isotope {

// What a reader knows about its volume without reading any value.
struct VolumeInfo {
  std::array<int64_t, 3> dims{0, 0, 0};
  std::array<double, 3> spacing{1, 1, 1};
  std::array<double, 3> origin{0, 0, 0};
  std::string type;         // element type as stored in the file: "uint8", "int16", "float32", ...
  int element_bytes = 0;    // bytes per element in the file
  bool is_integer = false;  // integer elements (stored losslessly as float when |v| <= 2^24)
};

class BoxReader {
 public:
  virtual ~BoxReader() = default;
  const VolumeInfo& info() const { return info_; }
  // Nodes lo .. lo+size-1 per axis (must lie inside info().dims, else InvalidInput),
  // x fastest then y then z, converted to float, into out[size[0]*size[1]*size[2]].
  // Safe to call concurrently from several threads. Throws IoError naming the file on a short
  // read, and naming the global (x, y, z) of the first NaN or infinite value in the box.
  virtual void read_box(const std::array<int64_t, 3>& lo, const std::array<int64_t, 3>& size, float* out) const = 0;
  // The same values, not checked for being finite: for a caller that looks at each value anyway
  // and, on one that is not, asks read_box for the error that names it. Checked unless a reader
  // can leave the check out.
  virtual void read_box_unchecked(const std::array<int64_t, 3>& lo, const std::array<int64_t, 3>& size,
                                  float* out) const {
    read_box(lo, size, out);
  }
  // Whether a box costs about its own bytes to read, whatever boxes were read before (raw data:
  // a read of its rows, or of the rows with the gaps between them), rather than whole units
  // around it decoded again for each box (a TIFF stack's strips, an HDF5 dataset's chunks): a
  // convert gathers the boxes of neighbouring tiles into one read only where it does not.
  virtual bool reads_box_alone() const { return false; }
  // Whether the values are in memory already (an array), so that holding a copy would gain nothing.
  virtual bool in_memory() const { return false; }
  // The type read_box_stored reads values as, for a reader that can read them as the file stores
  // them, not converted: integers of one or two bytes of either byte order, in raw data (a raw
  // file's, a raw or inflated NRRD's, a contiguous HDF5 dataset's), an HDF5 dataset or a TIFF stack,
  // delivered in this machine's order (swapped where read). None for any other.
  virtual std::optional<ScalarType> stored_type() const { return std::nullopt; }
  // The box's values as stored, element_bytes each, into out (only where stored_type() is not
  // none): for a caller that converts the few it needs to float. An integer is finite.
  virtual void read_box_stored(const std::array<int64_t, 3>& /*lo*/, const std::array<int64_t, 3>& /*size*/,
                               unsigned char* /*out*/) const {
    throw std::logic_error("this reader cannot read values as stored");
  }

 protected:
  VolumeInfo info_;
};

// What a reader of values of TYPE knows of its volume.
VolumeInfo volume_info(ScalarType type, const std::array<int64_t, 3>& dims, const std::array<double, 3>& spacing,
                       const std::array<double, 3>& origin);

// "(x,y,z)": a node or a box's size, as the readers' messages write them.
std::string coordinates_text(const std::array<int64_t, 3>& v);

// Throws InvalidInput, naming WHERE, unless the box of SIZE nodes at LO lies inside
// info.dims (a size of 0 is inside: it reads nothing). For the readers' read_box.
void check_box(const std::array<int64_t, 3>& lo, const std::array<int64_t, 3>& size, const VolumeInfo& info,
               const std::string& where);

// Same inputs as read_volume: raw (layout from the name or the overrides), FILE.h5:/dataset,
// FILE.h5 holding a single 3-D dataset, .nrrd/.nhdr, a TIFF stack. Checks at open what needs no value: the
// file size against dims * type for raw data, the dataset's existence, rank and type for HDF5.
// gzip-encoded NRRD cannot be read at random: it is inflated once, streaming, into a temporary
// raw file inside SCRATCH_DIR, removed when the reader is destroyed or the open fails.
// Throws IoError naming the file and what is wrong.
// HDF5_CHUNK_CACHE_BYTES: the most a chunked HDF5 dataset's reader may keep of decoded chunks, so
// that boxes of whole planes each decode a layer of chunks once (0: HDF5's default, 1 MB). Memory
// beside the caller's own, for as long as the reader lives.
std::unique_ptr<BoxReader> open_box_reader(const VolumeSpec& source, const std::string& scratch_dir,
                                           uint64_t hdf5_chunk_cache_bytes = 0);

}  // namespace isotope
