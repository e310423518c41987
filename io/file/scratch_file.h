#pragma once
// Scratch space for data that may be too large for memory: a nameless file created in a chosen
// directory and unlinked at once, so nothing is left behind however the process ends; or, when
// the caller can afford it, the same in memory. Any number of threads may use disjoint ranges
// at once.
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "engine/core/huge_blocks.h"

namespace isotope {

class ScratchFile {
 public:
  explicit ScratchFile(const std::string& directory);  // a file; throws IoError
  explicit ScratchFile(uint64_t memory_bytes);         // in memory, this size
  ~ScratchFile();
  ScratchFile(const ScratchFile&) = delete;
  ScratchFile& operator=(const ScratchFile&) = delete;

  // Whether the file system gives the file its first BYTES now (fallocate), so that writes within
  // them cannot meet a full disk; always so in memory.
  bool reserve(uint64_t bytes) const noexcept;
  void write(const void* data, size_t bytes, uint64_t offset) const;  // throws IoError (disk full)
  void read(void* data, size_t bytes, uint64_t offset) const;         // throws IoError

 private:
  std::string directory_;
  int fd_ = -1;
  std::vector<char, detail::HugePageAllocator<char>> memory_;
};

}  // namespace isotope
