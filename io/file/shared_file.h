#pragma once
// A file that several processes write at once, each its own byte ranges (pwrite, pread): the
// output's temporary file and the band hand-over of a distributed convert
// (convert_to_store), on a file system every rank sees. Unlike a scratch file it has a
// name, so that other processes can open it; whoever creates it removes it.
#include <cstddef>
#include <cstdint>
#include <string>

namespace isotope {

class SharedFile {
 public:
  enum class Mode { create, open };
  // create: a new file (it must not exist), removed again by the destructor; open: an existing
  // one. Throws IoError naming the path.
  SharedFile(std::string path, Mode mode);
  ~SharedFile();
  SharedFile(const SharedFile&) = delete;
  SharedFile& operator=(const SharedFile&) = delete;

  void write(const void* data, size_t bytes, uint64_t offset) const;  // throws IoError (disk full)
  void read(void* data, size_t bytes, uint64_t offset) const;         // throws IoError
  void sync() const;                                                  // fsync; throws IoError
  const std::string& path() const { return path_; }

 private:
  std::string path_;
  int fd_ = -1;
  bool remove_ = false;
  int registered_ = -1;  // register_temporary's slot
};

}  // namespace isotope
