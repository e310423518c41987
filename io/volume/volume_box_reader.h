#pragma once
// A volume already in memory as a BoxReader, so that it can be converted to a store without
// writing it to a file first (isotope bench converts generated volumes of up to 540 MB).
#include <cstring>
#include <stdexcept>

#include "io/volume/box_reader.h"
#include "isotope/error.h"
#include "isotope/volume.h"

namespace isotope {

class VolumeBoxReader final : public BoxReader {
 public:
  // VOLUME must outlive the reader.
  explicit VolumeBoxReader(const Volume& volume) : volume_(volume) {
    info_.dims = volume.dims;
    info_.spacing = volume.spacing;
    info_.origin = volume.origin;
    info_.type = "float32";
    info_.element_bytes = 4;
    info_.is_integer = false;
  }

  bool reads_box_alone() const override { return true; }
  bool in_memory() const override { return true; }
  void read_box(const std::array<int64_t, 3>& lo, const std::array<int64_t, 3>& size, float* out) const override {
    for (int a = 0; a < 3; ++a)
      if (lo[a] < 0 || size[a] < 0 || lo[a] + size[a] > volume_.dims[a]) throw InvalidInput("box outside the volume");
    for (int64_t z = 0; z < size[2]; ++z)
      for (int64_t y = 0; y < size[1]; ++y) {
        const float* row = volume_.data() + volume_.index(lo[0], lo[1] + y, lo[2] + z);
        std::memcpy(out, row, static_cast<size_t>(size[0]) * sizeof(float));
        out += size[0];
      }
  }

 private:
  const Volume& volume_;
};

}  // namespace isotope
