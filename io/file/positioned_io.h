#pragma once
// Reading and writing a whole buffer at an offset (pread, pwrite): what the files several threads
// or processes use at their own places share (io/file/atomic_file.h's regions, shared_file.h,
// scratch_file.h) with the readers of volumes and stores. Each caller words its own message.
#include <unistd.h>

#include <cerrno>
#include <cstddef>
#include <cstdint>

namespace isotope {

// Writes BYTES of DATA at OFFSET of FD, retrying short writes and interruptions. Returns 0, or the
// errno of the failure (ENOSPC when the disk took nothing, as a full one does), for the caller's
// message.
inline int pwrite_all(int fd, const void* data, size_t bytes, uint64_t offset) {
  const auto* p = static_cast<const unsigned char*>(data);
  while (bytes > 0) {
    const ssize_t n = ::pwrite(fd, p, bytes, static_cast<off_t>(offset));
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) return n < 0 ? errno : ENOSPC;
    p += n;
    offset += static_cast<uint64_t>(n);
    bytes -= static_cast<size_t>(n);
  }
  return 0;
}

// How pread_all ended: `bytes` read before the end of the span, the file's end, or a failure.
struct PreadOutcome {
  size_t bytes = 0;  // read into the buffer from its start
  int error = 0;     // errno of a failed read; 0 when the span was read or the file ended first
  bool ended_early(size_t asked) const { return error == 0 && bytes < asked; }
};

// Reads BYTES at OFFSET of FD into DATA, retrying short reads and interruptions, until the span is
// read, the file ends or a read fails.
inline PreadOutcome pread_all(int fd, void* data, size_t bytes, uint64_t offset) {
  auto* p = static_cast<unsigned char*>(data);
  PreadOutcome out;
  while (out.bytes < bytes) {
    const ssize_t n = ::pread(fd, p + out.bytes, bytes - out.bytes, static_cast<off_t>(offset + out.bytes));
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) out.error = errno;
    if (n <= 0) break;
    out.bytes += static_cast<size_t>(n);
  }
  return out;
}

}  // namespace isotope
