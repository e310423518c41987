#include "io/file/scratch_file.h"

#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <vector>

#include "io/file/positioned_io.h"
#include "isotope/error.h"

namespace isotope {

ScratchFile::ScratchFile(const std::string& directory) : directory_(directory) {
  std::string name = directory + "/.isotope-scratch-XXXXXX";
  std::vector<char> buf(name.begin(), name.end());
  buf.push_back('\0');
  fd_ = ::mkstemp(buf.data());
  if (fd_ < 0) throw IoError("cannot create a scratch file in '" + directory + "': " + std::strerror(errno));
  ::unlink(buf.data());
}

ScratchFile::ScratchFile(uint64_t memory_bytes) : memory_(static_cast<size_t>(memory_bytes)) {}

ScratchFile::~ScratchFile() {
  if (fd_ >= 0) ::close(fd_);
}

bool ScratchFile::reserve(uint64_t bytes) const noexcept {
  if (fd_ < 0) return bytes <= memory_.size();
  return bytes == 0 || ::fallocate(fd_, 0, 0, static_cast<off_t>(bytes)) == 0;
}

void ScratchFile::write(const void* data, size_t bytes, uint64_t offset) const {
  if (fd_ < 0) {
    if (offset + bytes > memory_.size()) throw IoError("scratch write past its end");
    std::memcpy(const_cast<char*>(memory_.data()) + offset, data, bytes);
    return;
  }
  if (const int err = pwrite_all(fd_, data, bytes, offset))
    throw IoError("cannot write scratch data in '" + directory_ +
                  "': " + (err == ENOSPC || err == EDQUOT ? "disk full" : std::strerror(err)));
}

void ScratchFile::read(void* data, size_t bytes, uint64_t offset) const {
  if (fd_ < 0) {
    if (offset + bytes > memory_.size()) throw IoError("scratch read past its end");
    std::memcpy(data, memory_.data() + offset, bytes);
    return;
  }
  const PreadOutcome r = pread_all(fd_, data, bytes, offset);
  if (r.bytes < bytes)
    throw IoError("cannot read scratch data in '" + directory_ + "'" +
                  (r.error != 0 ? std::string(": ") + std::strerror(r.error) : ""));
}

}  // namespace isotope
