#pragma once
// The input policy (the counterpart of AtomicFile's output policy): every file isotope
// reads is a regular file. A FIFO without a writer would block the open or the first read forever,
// a device such as /dev/zero never ends, so both are refused by name before anything opens them
// (`isotope extract some.fifo` used to hang; the test VolumeRead.NonRegularInputsAreRefused).
#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <filesystem>
#include <string>
#include <system_error>
#include <utility>

#include "isotope/error.h"

namespace isotope {

// Throws IoError "WHERE: no such file", "WHERE: is a directory, not KIND" or "WHERE: is a FIFO
// (device, socket), not a regular file"; links are followed.
inline void require_regular_file(const std::string& path, const std::string& where, const std::string& kind) {
  namespace fs = std::filesystem;
  std::error_code ec;
  const fs::file_status st = fs::status(path, ec);
  if (!fs::exists(st)) throw IoError(where + ": no such file");
  if (fs::is_directory(st)) throw IoError(where + ": is a directory, not " + kind);
  if (fs::is_regular_file(st)) return;
  const char* what = fs::is_fifo(st)                                      ? "a FIFO"
                     : fs::is_block_file(st) || fs::is_character_file(st) ? "a device"
                     : fs::is_socket(st)                                  ? "a socket"
                                                                          : "a special file";
  throw IoError(where + ": is " + what + ", not a regular file");
}

// errno's text; strerror may share a static buffer between threads, this does not.
inline std::string system_error_text(int err) { return std::error_code(err, std::generic_category()).message(); }

// A descriptor this process opened, closed when this goes.
class FileDescriptor {
 public:
  explicit FileDescriptor(int fd) : fd_(fd) {}
  FileDescriptor(FileDescriptor&& other) noexcept : fd_(std::exchange(other.fd_, -1)) {}
  FileDescriptor& operator=(FileDescriptor&&) = delete;
  FileDescriptor(const FileDescriptor&) = delete;
  FileDescriptor& operator=(const FileDescriptor&) = delete;
  ~FileDescriptor() {
    if (fd_ >= 0) ::close(fd_);
  }
  int get() const { return fd_; }

 private:
  int fd_;
};

// PATH opened to read, after require_regular_file(PATH, WHERE, KIND). Throws IoError "WHERE: cannot
// open: ..." too.
inline FileDescriptor open_input(const std::string& path, const std::string& where, const std::string& kind) {
  require_regular_file(path, where, kind);
  FileDescriptor fd(::open(path.c_str(), O_RDONLY | O_CLOEXEC));
  if (fd.get() < 0) throw IoError(where + ": cannot open: " + system_error_text(errno));
  return fd;
}

}  // namespace isotope
