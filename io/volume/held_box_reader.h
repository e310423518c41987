#pragma once
// A volume file read once, whole planes at a time in file order, and held in memory as it is
// stored: the boxes asked for then copy from memory. For a convert of a volume that fits in a share
// of its budget: a tile's box of raw data is read with the gaps between its rows (rows_a_call), so
// that tiles 33 nodes wide in a 257-wide volume copy each byte of the file out of the page cache
// about 8 times, one call a plane of each tile (docs/METHOD.md, "The input held whole").
#include <array>
#include <atomic>
#include <cstdint>
#include <exception>
#include <memory>
#include <mutex>

#include "engine/core/huge_blocks.h"
#include "io/volume/box_reader.h"

namespace isotope {

class HeldBoxReader final : public BoxReader {
 public:
  // INPUT must outlive the reader. Nothing is read until a box asks for it: the planes up to a
  // box's last are read then, by the thread that asks, while the others that need them wait, so
  // that the reads overlap the work on the planes read before (and a disk's read-ahead the rest).
  // READ_BYTES: about what one read of planes takes (at least a plane).
  explicit HeldBoxReader(const BoxReader& input, int64_t read_bytes = kReadBytes);
  static constexpr int64_t kReadBytes = int64_t{4} << 20;
  ~HeldBoxReader() override;
  HeldBoxReader(const HeldBoxReader&) = delete;
  HeldBoxReader& operator=(const HeldBoxReader&) = delete;

  // What the reader of INPUT holds once every plane is read: the values as the file stores them
  // (integers of one or two bytes, BoxReader::stored_type), or as float.
  static uint64_t held_bytes(const BoxReader& input);

  // Checked as INPUT checks them: a NaN or an infinite value fails every box that reaches the
  // planes read with it, with INPUT's message (the first such value of that read, in the file's
  // order), and the read is not tried again.
  void read_box(const std::array<int64_t, 3>& lo, const std::array<int64_t, 3>& size, float* out) const override;
  bool reads_box_alone() const override { return true; }
  bool in_memory() const override { return true; }

 private:
  void read_planes_to(int64_t end) const;  // planes [0, end) held, or throws

  // Bytes a node of INPUT is held in.
  static int64_t value_bytes_of(const BoxReader& input);
  const BoxReader& input_;
  bool stored_ = false;                     // held as stored (integers), else as float
  int64_t value_bytes_ = 0;                 // held bytes a node
  int64_t plane_nodes_ = 0;                 // nodes of a plane
  int64_t read_planes_ = 1;                 // planes a read
  detail::HugeArray<unsigned char> huge_;   // the held values: in huge pages,
  std::unique_ptr<unsigned char[]> small_;  // or, for a small volume, in the heap's
  unsigned char* held_ = nullptr;           // whichever holds them
  mutable std::mutex read_mutex_;
  mutable std::atomic<int64_t> held_planes_{0};
  mutable std::exception_ptr failed_;  // under read_mutex_: the read that failed, for every box after it
};

}  // namespace isotope
