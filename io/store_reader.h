#pragma once
// Reading a store (docs/FORMAT.md): header and directory at open, bricks on demand by pread
// (thread-safe), the whole store into memory for extraction, and a full verification.
#include <cstdint>
#include <string>
#include <vector>

#include "engine/multires_volume.h"
#include "engine/progress.h"
#include "engine/store_layout.h"
#include "io/store_format.h"

namespace isotope {

class StoreReader {
 public:
  // Reads and checks the header and the directory. Throws IoError naming the file.
  explicit StoreReader(const std::string& path);
  ~StoreReader();
  StoreReader(const StoreReader&) = delete;
  StoreReader& operator=(const StoreReader&) = delete;

  const std::string& path() const { return path_; }
  const StoreHeader& header() const { return header_; }
  const StoreLayout& layout() const { return layout_; }
  const std::vector<BrickEntry>& directory() const { return directory_; }
  uint64_t file_bytes() const { return file_bytes_; }

  // Brick `index` of the directory, checked and decoded. Throws IoError naming the brick.
  BrickContents read_brick(int64_t index) const;
  // Only the values the brick stores (band 0: the (T+4)^3 box with its halo, x fastest; other
  // bands: T^3 in Morton order), without rebuilding band 0's records.
  std::vector<float> read_stored_values(int64_t index) const;
  // Asks the kernel to start reading what follows brick `index` in the file (the next bricks of
  // its band in Morton order, i.e. traversal order), about `bricks` bricks' worth, in the
  // background: a hint that costs no thread and pays when the file is not in the page cache.
  void prefetch_after(int64_t index, int bricks) const;
  // "FILE: brick 12 (band 0, brick 1 0 0)"
  std::string describe_brick(int64_t index) const;
  // Band and brick coordinates of a directory index.
  std::pair<int, Box3> locate_brick(int64_t index) const;

  // The whole store as an in-memory volume, ready for extract(). Throws IoError.
  MultiresVolume load(const ProgressCallback& progress = {}) const;

 private:
  std::vector<uint8_t> read_compressed(int64_t index) const;

  std::string path_;
  int fd_ = -1;
  uint64_t file_bytes_ = 0;
  StoreHeader header_;
  StoreLayout layout_;
  std::vector<BrickEntry> directory_;
};

// True when PATH is a readable file that starts with the store's magic number.
bool is_store_file(const std::string& path);

// Reads every brick and checks every checksum and the format's invariants (see FORMAT.md,
// "Verification"). Throws IoError naming the first problem.
struct VerifyStats {
  int64_t bricks = 0;
  uint64_t compressed_bytes = 0, raw_bytes = 0;
};
VerifyStats verify_store(const std::string& path, const ProgressCallback& progress = {});

}  // namespace isotope
