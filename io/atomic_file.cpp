#include "io/atomic_file.h"

#include <fcntl.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <system_error>
#include <utility>

#include "io/io_error.h"

namespace isotope {
namespace {

namespace fs = std::filesystem;

std::string errno_text(int err) {
  if (err == ENOSPC || err == EDQUOT) return "disk full (" + std::string(std::strerror(err)) + ")";
  return std::strerror(err);
}

std::string directory_of(const std::string& path) {
  const fs::path dir = fs::path(path).parent_path();
  return dir.empty() ? std::string(".") : dir.string();
}

// Throws when the target's directory is missing, so the message names the real problem
// rather than a failed create of a temporary name the user never chose.
void require_directory(const std::string& path, const std::string& dir) {
  std::error_code ec;
  const fs::file_status st = fs::status(dir, ec);
  if (!fs::exists(st)) throw IoError(path + ": directory '" + dir + "' does not exist");
  if (!fs::is_directory(st)) throw IoError(path + ": '" + dir + "' is not a directory");
}

std::string temp_name(const std::string& path, const std::string& dir, unsigned serial) {
  const std::string name = fs::path(path).filename().string();
  return (fs::path(dir) / ("." + name + ".tmp." + std::to_string(::getpid()) + "." +
                           std::to_string(serial)))
      .string();
}

// Makes the rename itself durable; failure here only weakens crash safety, so it is ignored.
void sync_directory(const std::string& dir) {
  const int fd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (fd < 0) return;
  (void)::fsync(fd);
  (void)::close(fd);
}

}  // namespace

AtomicFile::AtomicFile(std::string path) : path_(std::move(path)) {
  if (path_.empty()) throw IoError("output path is empty");
  const std::string dir = directory_of(path_);
  require_directory(path_, dir);
  static std::atomic<unsigned> serial{0};
  // "x" (exclusive create) so two writers in one directory never share a temporary.
  for (int attempt = 0; attempt < 100 && file_ == nullptr; ++attempt) {
    temp_path_ = temp_name(path_, dir, serial.fetch_add(1));
    file_ = std::fopen(temp_path_.c_str(), "wbx");
    if (file_ == nullptr && errno != EEXIST) {
      const int err = errno;
      if (err == EACCES || err == EPERM || err == EROFS)
        throw IoError(path_ + ": directory '" + dir + "' is not writable (" + std::strerror(err) + ")");
      throw IoError(path_ + ": cannot create a file in '" + dir + "': " + errno_text(err));
    }
  }
  if (file_ == nullptr) throw IoError(path_ + ": cannot find a free temporary name in '" + dir + "'");
}

AtomicFile::~AtomicFile() {
  if (file_ != nullptr) std::fclose(file_);
  if (!committed_ && !temp_path_.empty()) std::remove(temp_path_.c_str());
}

void AtomicFile::write(const void* data, size_t bytes) {
  if (file_ == nullptr) throw IoError(path_ + ": write after commit");
  if (bytes == 0) return;
  errno = 0;
  if (std::fwrite(data, 1, bytes, file_) != bytes)
    throw IoError(path_ + ": write failed: " + errno_text(errno != 0 ? errno : EIO));
  size_ += bytes;
}

void AtomicFile::write_at(uint64_t offset, const void* data, size_t bytes) {
  if (file_ == nullptr) throw IoError(path_ + ": write after commit");
  if (offset + bytes > size_) throw IoError(path_ + ": write_at past the end of what was written");
  errno = 0;
  const bool ok = std::fseek(file_, static_cast<long>(offset), SEEK_SET) == 0 &&
                  std::fwrite(data, 1, bytes, file_) == bytes && std::fseek(file_, 0, SEEK_END) == 0;
  if (!ok) throw IoError(path_ + ": write failed: " + errno_text(errno != 0 ? errno : EIO));
}

void AtomicFile::commit() {
  if (file_ == nullptr) throw IoError(path_ + ": commit called twice");
  // Buffered data may only meet a full disk here, so flush and close are checked too.
  errno = 0;
  const bool flushed = std::fflush(file_) == 0 && ::fsync(::fileno(file_)) == 0;
  const int flush_err = errno;
  const bool closed = std::fclose(file_) == 0;
  const int close_err = errno;
  file_ = nullptr;
  if (!flushed) throw IoError(path_ + ": write failed: " + errno_text(flush_err != 0 ? flush_err : EIO));
  if (!closed) throw IoError(path_ + ": close failed: " + errno_text(close_err != 0 ? close_err : EIO));
  if (std::rename(temp_path_.c_str(), path_.c_str()) != 0)
    throw IoError(path_ + ": cannot rename temporary file into place: " + std::strerror(errno));
  committed_ = true;
  sync_directory(directory_of(path_));
}

}  // namespace isotope
