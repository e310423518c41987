#include "io/volume/raw_data_reader.h"

#include <algorithm>
#include <cstddef>
#include <memory>
#include <optional>
#include <stdexcept>
#include <utility>

#include "io/file/positioned_io.h"
#include "io/volume/raw_reader.h"
#include "isotope/error.h"

namespace isotope {
namespace {

// Bounds the staging buffer of one read_box call however large the box; a whole number of
// values of every type.
constexpr size_t kStageBytes = size_t{1} << 20;

// pread may return less than asked; only 0 (end of file) or an error end the loop early.
void pread_fully(int fd, unsigned char* out, size_t size, int64_t offset, const std::string& where) {
  const PreadOutcome r = pread_all(fd, out, size, static_cast<uint64_t>(offset));
  const int64_t at = offset + static_cast<int64_t>(r.bytes);
  if (r.error != 0)
    throw IoError(where + ": read failed at byte " + std::to_string(at) + ": " + system_error_text(r.error));
  if (r.ended_early(size)) {
    throw IoError(where + ": short read: the file ends at byte " + std::to_string(at) + ", before byte " +
                  std::to_string(offset + static_cast<int64_t>(size)) + " (was it truncated after opening?)");
  }
}

// Raw values at a byte offset of one file: each box is read with pread on a descriptor opened
// once, which needs no lock between threads.
class RawBoxReader final : public BoxReader {
 public:
  RawBoxReader(FileDescriptor fd, RawData data, const VolumeInfo& info, std::shared_ptr<const void> keep)
      : keep_(std::move(keep)), fd_(std::move(fd)), data_(std::move(data)) {
    info_ = info;
  }

  void read_box(const std::array<int64_t, 3>& lo, const std::array<int64_t, 3>& size, float* out) const override {
    read_box_unchecked(lo, size, out);
    if (!info_.is_integer) check_finite(out, lo, size, data_.name);  // an integer is finite as float
  }

  void read_box_unchecked(const std::array<int64_t, 3>& lo, const std::array<int64_t, 3>& size,
                          float* out) const override {
    check_box(lo, size, info_, data_.name);
    const int64_t total = size[0] * size[1] * size[2];
    if (total == 0) return;
    const int64_t run = run_length(size);
    const size_t elem = static_cast<size_t>(info_.element_bytes);
    const auto& d = info_.dims;
    const int64_t rows = rows_a_call(size);
    if (rows > 1) {
      Stage stage(static_cast<size_t>(((rows - 1) * d[0] + size[0])) * elem);
      for (int64_t z = 0; z < size[2]; ++z)
        for (int64_t y = 0; y < size[1]; y += rows) read_rows(lo, size, y, std::min(rows, size[1] - y), z, out, stage);
      return;
    }
    // Floats stored as this machine holds them are read straight into OUT: no stage, no copy.
    Stage stage(stored_as_floats() ? 0 : std::min(static_cast<size_t>(run) * elem, kStageBytes));
    for_each_run(lo, size, run, [&](int64_t done, int64_t node) { read_run(node, run, out + done, stage); });
  }

  bool reads_box_alone() const override { return true; }

  // Integers of one or two bytes, in this machine's byte order: those of the other order are
  // swapped where they are read, as HDF5 and libtiff swap theirs.
  std::optional<ScalarType> stored_type() const override {
    if (!info_.is_integer || info_.element_bytes > 2) return std::nullopt;
    return data_.type;
  }

  void read_box_stored(const std::array<int64_t, 3>& lo, const std::array<int64_t, 3>& size,
                       unsigned char* out) const override {
    if (!stored_type()) throw std::logic_error(data_.name + ": values cannot be read as stored");
    check_box(lo, size, info_, data_.name);
    const int64_t run = run_length(size);
    const int64_t elem = info_.element_bytes;
    const bool swap = elem == 2 && data_.swapped();
    for_each_run(lo, size, run, [&](int64_t done, int64_t node) {
      unsigned char* const at = out + done * elem;
      pread_fully(fd_.get(), at, static_cast<size_t>(run * elem), data_.offset + node * elem, data_.read_name);
      if (swap)
        for (int64_t i = 0; i < run; ++i) std::swap(at[2 * i], at[2 * i + 1]);
    });
  }

 private:
  // Calls f(done, node) for each run of RUN nodes of the box that is contiguous in the file (runs
  // of run_length(size)): DONE, the box's nodes before it; NODE, the file's index of its first.
  template <class F>
  void for_each_run(const std::array<int64_t, 3>& lo, const std::array<int64_t, 3>& size, int64_t run,
                    const F& f) const {
    const auto& d = info_.dims;
    const int64_t total = size[0] * size[1] * size[2];
    for (int64_t done = 0; done < total; done += run) {
      const int64_t y = lo[1] + done / size[0] % size[1];
      const int64_t z = lo[2] + done / (size[0] * size[1]);
      f(done, (z * d[1] + y) * d[0] + lo[0]);
    }
  }

  // Nodes of the box that are contiguous in the file: a row, or whole planes when the box spans
  // whole rows, or the whole box when it also spans whole planes.
  int64_t run_length(const std::array<int64_t, 3>& size) const {
    if (size[0] != info_.dims[0]) return size[0];
    if (size[1] != info_.dims[1]) return size[0] * size[1];
    return size[0] * size[1] * size[2];
  }

  // Rows of a box narrower than the volume read several at a call, the gaps between them with
  // them, when a gap is under a page: the page cache reads those pages from the disk anyway, and
  // copying a few KB costs less than a call (a tile's box in a 2048-wide uint8 volume is one call
  // a plane instead of one a row). 1: a row a call.
  int64_t rows_a_call(const std::array<int64_t, 3>& size) const {
    const int64_t elem = info_.element_bytes;
    if (size[0] == info_.dims[0] || size[1] < 2 || (info_.dims[0] - size[0]) * elem > 4096) return 1;
    const int64_t row = info_.dims[0] * elem;
    return std::min(size[1], (static_cast<int64_t>(kStageBytes) - size[0] * elem) / row + 1);
  }
  // Bytes read before they are decoded: not zero-filled, since each read writes them first.
  struct Stage {
    explicit Stage(size_t bytes) : data(bytes > 0 ? new unsigned char[bytes] : nullptr), size(bytes) {}
    std::unique_ptr<unsigned char[]> data;
    size_t size;
  };

  bool stored_as_floats() const { return data_.type == ScalarType::float32 && !data_.swapped(); }

  // ROWS rows of the box from its row Y of plane Z in one read through STAGE.
  void read_rows(const std::array<int64_t, 3>& lo, const std::array<int64_t, 3>& size, int64_t y, int64_t rows,
                 int64_t z, float* out, const Stage& stage) const {
    const int64_t elem = info_.element_bytes;
    const auto& d = info_.dims;
    const int64_t first = ((lo[2] + z) * d[1] + lo[1] + y) * d[0] + lo[0];
    pread_fully(fd_.get(), stage.data.get(), static_cast<size_t>(((rows - 1) * d[0] + size[0]) * elem),
                data_.offset + first * elem, data_.read_name);
    for (int64_t r = 0; r < rows; ++r)
      decode_scalars(data_.type, data_.big_endian, stage.data.get() + r * d[0] * elem, static_cast<size_t>(size[0]),
                     out + (z * size[1] + y + r) * size[0]);
  }

  // COUNT nodes from node index FIRST, through STAGE in pieces when they do not fit, or straight
  // into OUT without one.
  void read_run(int64_t first, int64_t count, float* out, const Stage& stage) const {
    const int64_t elem = info_.element_bytes;
    if (stage.size == 0) {
      pread_fully(fd_.get(), reinterpret_cast<unsigned char*>(out), static_cast<size_t>(count * elem),
                  data_.offset + first * elem, data_.read_name);
      return;
    }
    const int64_t piece = static_cast<int64_t>(stage.size) / elem;
    for (int64_t i = 0; i < count; i += piece) {
      const int64_t n = std::min(piece, count - i);
      pread_fully(fd_.get(), stage.data.get(), static_cast<size_t>(n * elem), data_.offset + (first + i) * elem,
                  data_.read_name);
      decode_scalars(data_.type, data_.big_endian, stage.data.get(), static_cast<size_t>(n), out + i);
    }
  }

  std::shared_ptr<const void> keep_;  // what fd_ reads, where that goes with the reader (an inflated copy)
  FileDescriptor fd_;
  RawData data_;
};

}  // namespace

std::unique_ptr<BoxReader> open_raw_data(FileDescriptor fd, RawData data, const VolumeInfo& info,
                                         std::shared_ptr<const void> keep) {
  return std::make_unique<RawBoxReader>(std::move(fd), std::move(data), info, std::move(keep));
}

}  // namespace isotope
