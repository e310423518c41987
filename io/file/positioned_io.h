#pragma once
// Reading and writing a whole buffer at an offset (pread, pwrite): what the files several threads
// or processes use at their own places share (AtomicFile's regions, SharedFile,
// ScratchFile) with the readers of volumes and stores. Each caller words its own message.
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <new>

#include "engine/core/huge_blocks.h"

namespace isotope {

// The kernel copies between the page cache and a buffer with `rep movsb`, which on some x86 cores
// runs several times slower when the destination lies a few bytes past the source modulo 4 KB: on
// the reference machine (AMD EPYC), a 9 MB read at a page-aligned offset into a buffer 16 bytes
// into its page moved 1.6 GB/s, and 9 GB/s at 0 or 32 and beyond. A buffer of that size from malloc
// lies exactly 16 bytes into its page. So a transfer in that case goes through a bounce buffer
// placed at the file's offset within the page, a piece at a time, and user space's memcpy (which
// steers clear of the case) moves the bytes between it and the caller's buffer (docs/METHOD.md,
// "Reading and writing files").
namespace positioned_detail {

inline constexpr size_t kPage = detail::kPageBytes;
inline constexpr size_t kAliasWindow = 64;       // distances of 1 to 63 bytes go through the bounce
inline constexpr size_t kBounceMinBytes = 4096;  // below, the copy is too short to matter
inline constexpr size_t kBounceBytes = size_t{1} << 20;

// Whether a copy from SOURCE to DESTINATION puts the destination 1 to 63 bytes ahead of the source
// modulo a page (addresses; a file's offset stands for its page cache's place: the destination of
// a write, the source of a read).
inline bool slow_copy(uintptr_t destination, uintptr_t source) {
  const size_t distance = (destination - source) & (kPage - 1);
  return distance != 0 && distance < kAliasWindow;
}

// This thread's bounce buffer (kBounceBytes and a page), made on first use; null when memory is out
// (the transfer then goes direct, slowly but correctly).
inline unsigned char* bounce_buffer() {
  struct Free {
    void operator()(unsigned char* p) const { std::free(p); }
  };
  thread_local std::unique_ptr<unsigned char, Free> buffer(
      static_cast<unsigned char*>(std::aligned_alloc(kPage, kBounceBytes + kPage)));
  return buffer.get();
}

// Where in the bounce buffer a piece at file OFFSET goes: at the same offset within its page.
inline unsigned char* bounce_at(unsigned char* bounce, uint64_t offset) { return bounce + (offset & (kPage - 1)); }

}  // namespace positioned_detail

// Writes BYTES of DATA at OFFSET of FD, retrying short writes and interruptions. Returns 0, or the
// errno of the failure (ENOSPC when the disk took nothing, as a full one does), for the caller's
// message.
inline int pwrite_all(int fd, const void* data, size_t bytes, uint64_t offset) {
  namespace pd = positioned_detail;
  const auto* p = static_cast<const unsigned char*>(data);
  if (bytes >= pd::kBounceMinBytes && pd::slow_copy(static_cast<uintptr_t>(offset), reinterpret_cast<uintptr_t>(p)))
    if (unsigned char* bounce = pd::bounce_buffer()) {
      while (bytes > 0) {
        const size_t piece = std::min(bytes, pd::kBounceBytes);
        unsigned char* at = pd::bounce_at(bounce, offset);
        std::memcpy(at, p, piece);
        if (const int err = pwrite_all(fd, at, piece, offset)) return err;
        p += piece, offset += piece, bytes -= piece;
      }
      return 0;
    }
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
  namespace pd = positioned_detail;
  auto* p = static_cast<unsigned char*>(data);
  PreadOutcome out;
  if (bytes >= pd::kBounceMinBytes && pd::slow_copy(reinterpret_cast<uintptr_t>(p), static_cast<uintptr_t>(offset)))
    if (unsigned char* bounce = pd::bounce_buffer()) {
      while (out.bytes < bytes) {
        const size_t piece = std::min(bytes - out.bytes, pd::kBounceBytes);
        unsigned char* at = pd::bounce_at(bounce, offset + out.bytes);
        const PreadOutcome r = pread_all(fd, at, piece, offset + out.bytes);
        std::memcpy(p + out.bytes, at, r.bytes);
        out.bytes += r.bytes;
        out.error = r.error;
        if (r.bytes < piece) break;
      }
      return out;
    }
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
