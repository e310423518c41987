#include "io/file/shared_file.h"

#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

#include "io/file/positioned_io.h"
#include "io/file/temporary_registry.h"
#include "isotope/error.h"

namespace isotope {

SharedFile::SharedFile(std::string path, Mode mode) : path_(std::move(path)) {
  fd_ = mode == Mode::create ? ::open(path_.c_str(), O_RDWR | O_CREAT | O_EXCL | O_CLOEXEC, 0644)
                             : ::open(path_.c_str(), O_RDWR | O_CLOEXEC);
  if (fd_ < 0)
    throw IoError("cannot " + std::string(mode == Mode::create ? "create" : "open") + " '" + path_ +
                  "': " + std::strerror(errno));
  remove_ = mode == Mode::create;
  if (remove_) registered_ = register_temporary(path_);
}

SharedFile::~SharedFile() {
  if (fd_ >= 0) ::close(fd_);
  if (remove_) ::unlink(path_.c_str());
  unregister_temporary(registered_);
}

void SharedFile::write(const void* data, size_t bytes, uint64_t offset) const {
  if (const int err = pwrite_all(fd_, data, bytes, offset))
    throw IoError(path_ + ": write failed: " + std::strerror(err));
}

void SharedFile::read(void* data, size_t bytes, uint64_t offset) const {
  const PreadOutcome r = pread_all(fd_, data, bytes, offset);
  if (r.error != 0) throw IoError(path_ + ": read failed: " + std::strerror(r.error));
  if (r.ended_early(bytes)) throw IoError(path_ + ": read past the end");
}

void SharedFile::sync() const {
  if (::fsync(fd_) != 0) throw IoError(path_ + ": write failed: " + std::strerror(errno));
}

}  // namespace isotope
