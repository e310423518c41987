#pragma once
// Reading a store (docs/FORMAT.md): the header at open, a band's directory the first time one of
// its bricks is asked for (a coarse extraction never loads band 0's, nine tenths of them), bricks
// on demand by pread, section by section (thread-safe), and a full verification.
#include <array>
#include <atomic>
#include <bit>
#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <utility>
#include <vector>

#include "engine/core/huge_blocks.h"
#include "engine/core/progress_reporter.h"
#include "engine/hierarchy/hierarchy.h"
#include "engine/hierarchy/store_layout.h"
#include "io/store/store_format.h"

namespace isotope {

class StoreReader {
 public:
  // Reads and checks the header. Throws IoError naming the file.
  explicit StoreReader(const std::string& path);
  ~StoreReader();
  StoreReader(const StoreReader&) = delete;
  StoreReader& operator=(const StoreReader&) = delete;

  const std::string& path() const { return path_; }
  const StoreHeader& header() const { return header_; }
  const StoreLayout& layout() const { return layout_; }
  uint64_t file_bytes() const { return file_bytes_; }
  // Where the bricks end and the directories begin.
  uint64_t brick_area_end() const { return area_end_; }

  // Brick `index` of the directory order (StoreLayout). Loads and checks its band's
  // directory on first use; throws IoError naming the file when that fails.
  const BrickEntry& entry(int64_t index) const;
  // Reads the brick's sections that `which` names with as few preads as they take, checks and
  // decodes them into `out` (whose arrays for those sections must be present; values into
  // `values`). Returns the bytes read. Throws IoError naming the brick.
  // `narrow`: a one-byte store's values into bytes and core words into 32 bits instead
  // (decode_section).
  uint64_t read_brick(int64_t index, const StoreSections& which, const BrickView& out, float* values,
                      const NarrowBrick* narrow = nullptr) const;
  // Asks the kernel to start reading those sections in the background, with their read window:
  // a hint that costs no thread and pays when the file is not in the page cache. Nothing until
  // hints_pay().
  void prefetch(int64_t index, const StoreSections& which) const;
  // Whether hints pay: some read has found the page cache without its bytes. A store read wholly
  // from the page cache would pay a system call per hint for nothing (thousands in an
  // extraction). Once true, true for the reader's life: a store kept open (a server) that was read
  // cold once goes on hinting a brick each time its cache decodes it anew, even when the file is
  // back in the page cache.
  bool hints_pay() const { return read_waits() > 0; }
  // Reads that found bytes missing from the page cache and waited for the disk (on a file system
  // without RWF_NOWAIT, every read: it cannot tell), and the hints passed to the kernel, so far.
  // Thread-safe.
  int64_t read_waits() const { return waits_.load(std::memory_order_relaxed); }
  int64_t read_hints() const { return hints_.load(std::memory_order_relaxed); }
  // What the kernel reads of the file when a brick is not in the page cache: the aligned window
  // of this many bytes that holds it. Bricks lie in traversal order (docs/FORMAT.md, "File
  // order"), so the window mostly holds the next bricks a subtree reads: one read where there
  // were several (docs/METHOD.md, "Out of core").
  static constexpr uint64_t kReadWindow = uint64_t{64} << 10;
  static_assert(std::has_single_bit(kReadWindow), "windows are aligned by masking");
  // "FILE: brick 12 (band 0, brick 1 0 0)"
  std::string describe_brick(int64_t index) const;
  // Band and brick coordinates of a directory index.
  std::pair<int, Box3> locate_brick(int64_t index) const;

 private:
  // A large array (detail::HugePageAllocator): a band's directory is megabytes (24 bytes a brick)
  // read at once (docs/METHOD.md, "Out of core").
  using Directory = std::vector<BrickEntry, detail::HugePageAllocator<BrickEntry>>;
  const Directory& band_directory(int band) const;
  // Asks the kernel for the read windows that hold [begin, stop), none past the bricks' area.
  void advise_window(uint64_t begin, uint64_t stop) const;
  // [begin, stop) of the file into data, from the page cache when it holds it all, else with
  // its window; brick `index` names the file in an error.
  void read_range(uint8_t* data, uint64_t begin, uint64_t stop, int64_t index) const;

  std::string path_;
  int fd_ = -1;
  uint64_t file_bytes_ = 0, area_end_ = 0;
  StoreHeader header_;
  StoreLayout layout_;
  struct LazyDirectory {
    std::mutex mutex;
    std::shared_ptr<const Directory> entries;
  };
  std::unique_ptr<LazyDirectory[]> directories_;
  mutable std::atomic<int64_t> waits_{0}, hints_{0};  // read_waits(), read_hints()
};

// True when PATH is a readable file that starts with the store's magic number.
bool is_store_file(const std::string& path);

// Reads every brick and checks every checksum and the format's invariants (see FORMAT.md,
// "Verification"). Throws IoError naming the first problem.
struct VerifyStats {
  int64_t bricks = 0;
  uint64_t compressed_bytes = 0;
};
VerifyStats verify_store(const std::string& path, const ProgressCallback& progress = {});

}  // namespace isotope
