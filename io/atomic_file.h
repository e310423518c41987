#pragma once
// An output file that appears under its name only when complete: written to a temporary
// name in the same directory, renamed by commit(), removed if destroyed before that.
#include <cstdint>
#include <cstdio>
#include <string>

namespace isotope {

class AtomicFile {
 public:
  explicit AtomicFile(std::string path);  // throws IoError when the directory is not writable
  ~AtomicFile();
  AtomicFile(const AtomicFile&) = delete;
  AtomicFile& operator=(const AtomicFile&) = delete;

  void write(const void* data, size_t bytes);  // throws IoError (e.g. disk full)
  // Overwrites bytes already written (a header completed last); the next write() appends.
  void write_at(uint64_t offset, const void* data, size_t bytes);
  uint64_t size() const { return size_; }      // bytes written so far
  void commit();                               // flush, fsync, rename; throws IoError
  const std::string& temp_path() const { return temp_path_; }

 private:
  std::string path_, temp_path_;
  std::FILE* file_ = nullptr;
  bool committed_ = false;
  uint64_t size_ = 0;
};

}  // namespace isotope
