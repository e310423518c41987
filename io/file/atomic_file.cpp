#include "io/file/atomic_file.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <functional>
#include <stdexcept>
#include <system_error>
#include <utility>
#include <vector>

#include "io/file/direct_appends.h"
#include "io/file/positioned_io.h"
#include "io/file/region_writes.h"
#include "io/file/temporary_registry.h"
#include "isotope/error.h"

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
  return (fs::path(dir) / ("." + name + ".tmp." + std::to_string(::getpid()) + "." + std::to_string(serial))).string();
}

// Makes the rename itself durable; failure here only weakens crash safety, so it is ignored.
void sync_directory(const std::string& dir) {
  const int fd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (fd < 0) return;
  (void)::fsync(fd);
  (void)::close(fd);
}

const char* kind_of(mode_t mode) {
  if (S_ISDIR(mode)) return "a directory";
  if (S_ISCHR(mode)) return "a character device";
  if (S_ISBLK(mode)) return "a block device";
  if (S_ISFIFO(mode)) return "a FIFO";
  if (S_ISSOCK(mode)) return "a socket";
  return "not a regular file";
}

}  // namespace

std::string output_target(const std::string& path) {
  if (path.empty()) throw IoError("output path is empty");
  fs::path target = path;
  for (int links = 0;; ++links) {
    struct stat st {};
    if (::lstat(target.c_str(), &st) != 0) return target.string();  // a new file
    if (S_ISREG(st.st_mode)) return target.string();
    if (!S_ISLNK(st.st_mode))
      throw IoError(path + ": " + (target.string() == path ? "is " : "names '" + target.string() + "', ") +
                    kind_of(st.st_mode) + "; isotope writes regular files only and never replaces anything else");
    if (links == 40) throw IoError(path + ": too many levels of symbolic links");
    std::error_code ec;
    const fs::path next = fs::read_symlink(target, ec);
    if (ec) throw IoError(path + ": cannot read the symbolic link '" + target.string() + "': " + ec.message());
    target = next.is_absolute() ? next : target.parent_path() / next;
  }
}

void check_outputs(const std::vector<NamedPath>& inputs, const std::vector<NamedPath>& outputs) {
  struct Seen {
    const NamedPath* named;
    std::string target;  // output_target, made absolute
    bool exists = false;
    dev_t dev = 0;
    ino_t ino = 0;
  };
  auto identify = [](const NamedPath& p, std::string target) {
    Seen s{&p, std::move(target)};
    struct stat st {};
    if (::stat(s.target.c_str(), &st) == 0) {
      s.exists = true;
      s.dev = st.st_dev;
      s.ino = st.st_ino;
    }
    std::error_code ec;
    const fs::path absolute = fs::weakly_canonical(s.target, ec);
    if (!ec) s.target = absolute.string();
    return s;
  };
  std::vector<Seen> in, out;
  for (const NamedPath& p : inputs) {
    if (p.path.empty()) continue;
    Seen s = identify(p, p.path);
    // FILE.h5:/dataset names a file before its last ":/" (as read_volume splits it).
    const size_t split = p.path.rfind(":/");
    if (!s.exists && split != std::string::npos) s = identify(p, p.path.substr(0, split));
    in.push_back(s);
  }
  for (const NamedPath& p : outputs)
    if (!p.path.empty()) out.push_back(identify(p, output_target(p.path)));
  auto same = [](const Seen& a, const Seen& b) {
    return (a.exists && b.exists) ? a.dev == b.dev && a.ino == b.ino : a.target == b.target;
  };
  for (size_t i = 0; i < out.size(); ++i) {
    for (const Seen& s : in)
      if (same(out[i], s))
        throw IoError(out[i].named->what + " " + out[i].named->path + ": is the same file as " + s.named->what + " " +
                      s.named->path + "; isotope does not overwrite its input");
    for (size_t j = 0; j < i; ++j)
      if (same(out[i], out[j]))
        throw IoError(out[i].named->what + " " + out[i].named->path + ": is the same file as " + out[j].named->what +
                      " " + out[j].named->path + "; each output needs its own file");
  }
}

AtomicFile::AtomicFile(std::string path, Appends appends) : path_(std::move(path)) {
  if (path_.empty()) throw IoError("output path is empty");
  target_ = output_target(path_);
  const std::string dir = directory_of(target_);
  require_directory(path_, dir);
  static std::atomic<unsigned> serial{0};
  // "x" (exclusive create) so two writers in one directory never share a temporary.
  for (int attempt = 0; attempt < 100 && file_ == nullptr; ++attempt) {
    temp_path_ = temp_name(target_, dir, serial.fetch_add(1));
    file_ = std::fopen(temp_path_.c_str(), "wbx");
    if (file_ == nullptr && errno != EEXIST) {
      const int err = errno;
      if (err == EACCES || err == EPERM || err == EROFS)
        throw IoError(path_ + ": directory '" + dir + "' is not writable (" + std::strerror(err) + ")");
      throw IoError(path_ + ": cannot create a file in '" + dir + "': " + errno_text(err));
    }
  }
  if (file_ == nullptr) throw IoError(path_ + ": cannot find a free temporary name in '" + dir + "'");
  // At once: a signal that ends the process between the file's creation and this leaves it behind.
  registered_ = register_temporary(temp_path_);
  // Appends of a few KB each (a store's brick sections, a mesh's rows) in few calls: stdio's own
  // buffer is a page, a call for every 4 KB (and glibc takes a size only with a buffer).
  buffer_ = std::make_unique_for_overwrite<char[]>(kBufferBytes);
  std::setvbuf(file_, buffer_.get(), _IOFBF, kBufferBytes);
  transient_ = appends == Appends::transient;
  if (appends == Appends::direct) {
    // Where the file system refuses O_DIRECT, the writer thread writes the same buffers through
    // the page cache; where no thread can start, the appends go to stdio, as any other output's.
    direct_fd_ = ::open(temp_path_.c_str(), O_WRONLY | O_DIRECT | O_CLOEXEC);
    try {
      direct_ = std::make_unique<DirectAppends>(direct_fd_, ::fileno(file_));
    } catch (const std::exception&) {
      end_direct();
    }
  }
}

AtomicFile::~AtomicFile() {
  end_direct();
  region_writes_.reset();
  if (region_fd_ >= 0) ::close(region_fd_);
  if (file_ != nullptr) std::fclose(file_);
  if (!committed_ && !temp_path_.empty()) std::remove(temp_path_.c_str());
  unregister_temporary(registered_);
}

void AtomicFile::write(const void* data, size_t bytes) {
  if (file_ == nullptr) throw IoError(path_ + ": write after finish");
  if (bytes == 0) return;
  if (direct_) {
    if (const int err = direct_->append(data, bytes)) throw IoError(path_ + ": write failed: " + errno_text(err));
    size_ += bytes;
    return;
  }
  errno = 0;
  if (std::fwrite(data, 1, bytes, file_) != bytes)
    throw IoError(path_ + ": write failed: " + errno_text(errno != 0 ? errno : EIO));
  size_ += bytes;
}

void AtomicFile::write_at(uint64_t offset, const void* data, size_t bytes) {
  if (file_ == nullptr) throw IoError(path_ + ": write after finish");
  if (offset + bytes > size_) throw IoError(path_ + ": write_at past the end of what was written");
  if (direct_) {
    if (const int err = direct_->overwrite(offset, data, bytes))
      throw IoError(path_ + ": write failed: " + errno_text(err));
    return;
  }
  errno = 0;
  // Back to where the next write() appends: size_, which lies past the end of the file while a
  // region appended is not yet filled.
  const bool ok = fseeko(file_, static_cast<off_t>(offset), SEEK_SET) == 0 &&
                  std::fwrite(data, 1, bytes, file_) == bytes &&
                  fseeko(file_, static_cast<off_t>(size_), SEEK_SET) == 0;
  if (!ok) throw IoError(path_ + ": write failed: " + errno_text(errno != 0 ? errno : EIO));
}

uint64_t AtomicFile::append_region(uint64_t bytes) {
  const uint64_t at = size_;
  continue_at(at + bytes);
  // Opened once, on the first large region: a small mesh's file never asks for it. Without the
  // descriptor, or memory and a thread for the writes, regions go through the page cache.
  if (bytes >= kDirectRegionBytes && !region_tried_ && !transient_) {
    region_tried_ = true;
    region_fd_ = ::open(temp_path_.c_str(), O_WRONLY | O_DIRECT | O_CLOEXEC);
    if (region_fd_ >= 0) {
      try {
        region_writes_ = std::make_unique<RegionWrites>(region_fd_, ::fileno(file_), kRegionPieceBytes);
      } catch (const std::exception&) {
      }
    }
  }
  return at;
}

void AtomicFile::check_region(uint64_t offset, size_t bytes) const {
  if (file_ == nullptr) throw IoError(path_ + ": write after finish");
  if (offset + bytes > size_) throw IoError(path_ + ": write_region past the regions appended");
}

namespace {
// The whole pages of BYTES at OFFSET: [first, last) (empty where last <= first).
std::pair<uint64_t, uint64_t> whole_pages(uint64_t offset, size_t bytes) {
  constexpr uint64_t kPage = detail::kPageBytes;
  return {(offset + kPage - 1) & ~(kPage - 1), (offset + bytes) & ~(kPage - 1)};
}
}  // namespace

bool AtomicFile::goes_direct(uint64_t offset, size_t bytes) const {
  const auto [first, last] = whole_pages(offset, bytes);
  return region_writes_ && last > first && last - first >= kMinDirectBytes;
}

void AtomicFile::write_direct(uint64_t offset, const unsigned char* p, size_t bytes, unsigned char* in_buffer) const {
  const auto [first, last] = whole_pages(offset, bytes);
  // Through the page cache, a mesh's copy into fresh pages took a third of a one-shot eps 0's
  // processor time, and parallel buffered writes queued on the file's lock; a direct write made
  // by the thread that encoded the piece held it back from encoding the next (docs/METHOD.md,
  // "Reading and writing files"). So the partial pages at the two ends go through the page cache
  // here, and the whole pages to the writer thread, in a buffer of its own.
  const int buffered = ::fileno(file_);
  int err = pwrite_all(buffered, p, first - offset, offset);
  if (err == 0) err = pwrite_all(buffered, p + (last - offset), offset + bytes - last, last);
  if (err != 0) {
    if (in_buffer != nullptr) region_writes_->give_back(in_buffer);
    throw IoError(path_ + ": write failed: " + errno_text(err));
  }
  if (in_buffer != nullptr) {  // placed as the file's pages are: handed over as it is
    region_writes_->submit(in_buffer, p + (first - offset), last - first, first);
    return;
  }
  for (uint64_t at = first; at < last;) {
    const size_t piece = static_cast<size_t>(std::min<uint64_t>(last - at, kRegionPieceBytes));
    unsigned char* buffer = region_writes_->take(err);
    if (buffer == nullptr) throw IoError(path_ + ": write failed: " + errno_text(err));
    std::memcpy(buffer, p + (at - offset), piece);
    region_writes_->submit(buffer, buffer, piece, at);
    at += piece;
  }
}

void AtomicFile::write_region(uint64_t offset, const void* data, size_t bytes) const {
  check_region(offset, bytes);
  if (goes_direct(offset, bytes)) return write_direct(offset, static_cast<const unsigned char*>(data), bytes, nullptr);
  if (const int err = write_region_buffered(offset, data, bytes))
    throw IoError(path_ + ": write failed: " + errno_text(err));
}

int AtomicFile::write_region_buffered(uint64_t offset, const void* data, size_t bytes) const {
  const int buffered = ::fileno(file_);
  if (const int err = pwrite_all(buffered, data, bytes, offset)) return err;
  if (transient_) return 0;
  // The disk's writeback of these bytes starts now, on this thread, while the other threads still
  // encode theirs: finish()'s fsync then waits for less (a hint; what fails shows at the fsync).
  static_cast<void>(
      ::sync_file_range(buffered, static_cast<off_t>(offset), static_cast<off_t>(bytes), SYNC_FILE_RANGE_WRITE));
  return 0;
}

void AtomicFile::fill_region(uint64_t offset, size_t bytes, const std::function<void(unsigned char*)>& fill) const {
  if (bytes > kRegionPieceBytes) throw std::logic_error("fill_region: more than a piece");
  check_region(offset, bytes);
  if (goes_direct(offset, bytes)) {
    // A buffer of the writer's holds a piece and a page: room for the piece at the file offset's
    // place in its page, so that its whole pages are handed over with no copy.
    int err = 0;
    unsigned char* buffer = region_writes_->take(err);
    if (buffer == nullptr) throw IoError(path_ + ": write failed: " + errno_text(err));
    unsigned char* p = positioned_detail::bounce_at(buffer, offset);
    try {
      fill(p);
    } catch (...) {
      region_writes_->give_back(buffer);
      throw;
    }
    return write_direct(offset, p, bytes, buffer);
  }
  // Through the page cache: into this thread's bounce buffer where the piece fits (no fresh memory
  // for each piece), placed as the file's pages are, so that the write needs no bounce of its own.
  unsigned char* bounce = bytes <= positioned_detail::kBounceBytes ? positioned_detail::bounce_buffer() : nullptr;
  std::unique_ptr<unsigned char[]> own;
  if (bounce == nullptr) own = std::make_unique_for_overwrite<unsigned char[]>(bytes);
  unsigned char* p = bounce != nullptr ? positioned_detail::bounce_at(bounce, offset) : own.get();
  fill(p);
  if (const int err = write_region_buffered(offset, p, bytes))
    throw IoError(path_ + ": write failed: " + errno_text(err));
}

void AtomicFile::continue_at(uint64_t offset) {
  if (file_ == nullptr) throw IoError(path_ + ": write after finish");
  drain_direct();
  errno = 0;
  if (std::fflush(file_) != 0 || fseeko(file_, static_cast<off_t>(offset), SEEK_SET) != 0)
    throw IoError(path_ + ": write failed: " + errno_text(errno != 0 ? errno : EIO));
  size_ = offset;
}

void AtomicFile::finish() {
  if (finished_) return;
  if (file_ == nullptr) throw IoError(path_ + ": finish after commit");
  drain_direct();
  if (region_writes_) {
    // Kept after a failure, which it reports again: a second finish() or commit() must not
    // commit a file missing the bytes that failed.
    if (const int err = region_writes_->drain()) throw IoError(path_ + ": write failed: " + errno_text(err));
    region_writes_.reset();
  }
  if (region_fd_ >= 0) ::close(region_fd_);  // its writes are done: each returned when the disk had it
  region_fd_ = -1;
  // Buffered data may only meet a full disk here, so flush and close are checked too.
  errno = 0;
  const bool flushed = std::fflush(file_) == 0 && (transient_ || ::fsync(::fileno(file_)) == 0);
  const int flush_err = errno;
  const bool closed = std::fclose(file_) == 0;
  const int close_err = errno;
  file_ = nullptr;
  if (!flushed) throw IoError(path_ + ": write failed: " + errno_text(flush_err != 0 ? flush_err : EIO));
  if (!closed) throw IoError(path_ + ": close failed: " + errno_text(close_err != 0 ? close_err : EIO));
  finished_ = true;
}

void AtomicFile::drain_direct() {
  if (!direct_) return;
  const int err = direct_->drain();
  end_direct();
  if (err != 0) throw IoError(path_ + ": write failed: " + errno_text(err));
}

void AtomicFile::end_direct() {
  direct_.reset();
  if (direct_fd_ >= 0) ::close(direct_fd_);
  direct_fd_ = -1;
}

void AtomicFile::commit() {
  if (committed_) throw IoError(path_ + ": commit called twice");
  finish();
  if (std::rename(temp_path_.c_str(), target_.c_str()) != 0)
    throw IoError(path_ + ": cannot rename temporary file into place: " + std::strerror(errno));
  committed_ = true;
  unregister_temporary(registered_);
  registered_ = -1;
  if (!transient_) sync_directory(directory_of(target_));
}

}  // namespace isotope
