#pragma once
// Writing a whole buffer at an offset with pwrite: what the files several threads or processes
// write at their own places share (io/file/atomic_file.h's regions, shared_file.h, scratch_file.h).
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

}  // namespace isotope
