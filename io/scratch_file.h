#pragma once
// A nameless scratch file for data too large for memory: created in a chosen directory and
// unlinked at once, so nothing is left behind however the process ends. pread/pwrite only, so
// any number of threads may use disjoint ranges at once.
#include <cstddef>
#include <cstdint>
#include <string>

namespace isotope {

class ScratchFile {
 public:
  explicit ScratchFile(const std::string& directory);  // throws IoError
  ~ScratchFile();
  ScratchFile(const ScratchFile&) = delete;
  ScratchFile& operator=(const ScratchFile&) = delete;

  void write(const void* data, size_t bytes, uint64_t offset) const;  // throws IoError (disk full)
  void read(void* data, size_t bytes, uint64_t offset) const;         // throws IoError

 private:
  std::string directory_;
  int fd_ = -1;
};

}  // namespace isotope
