#pragma once
// The appends of a large output written past the page cache (O_DIRECT), a buffer at a time by a
// writer thread of their own while the caller goes on producing the next.
//
// Why: a store of a float volume is as large as its input, and copying it into the page cache
// (into pages the kernel must first find, and a virtual machine back) cost a sixth of a convert's
// processor time (docs/METHOD.md, "Reading and writing files"). A direct write
// moves the bytes from the buffer to the disk.
//
// Every few MB written, a thread of its own makes them durable (fdatasync) while the caller goes
// on: the fsync that commits the output then waits for the last few MB alone, not for the whole
// file's blocks and the disk's flush (docs/METHOD.md, "A store is appended past the page cache").
//
// The appends start at offset 0 of the file. Whole buffers (aligned in memory and in the file) go
// through DIRECT. Through BUFFERED go the last, partial buffer, overwrites of bytes already
// written, and every write once a direct one was refused (EINVAL: a file system or device that
// takes no such writes, or wants another alignment): the bytes on disk are the same either way.
#include <atomic>
#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <mutex>
#include <thread>

#include "engine/core/huge_blocks.h"

namespace isotope {

class DirectAppends {
 public:
  // DIRECT: the file opened with O_DIRECT, or -1 to write all through BUFFERED, the same file
  // opened without it. Neither is closed here. Throws std::bad_alloc without memory for the
  // buffers, std::system_error when no thread can start.
  DirectAppends(int direct, int buffered);
  ~DirectAppends();  // waits for a write or a sync under way; an error not yet reported is dropped
  DirectAppends(const DirectAppends&) = delete;
  DirectAppends& operator=(const DirectAppends&) = delete;

  // Each returns 0, or the errno of the first write or sync that failed (that one, or an earlier
  // one the writer or the syncer thread met); after a failure the file's content means nothing.
  int append(const void* data, size_t bytes);
  // Overwrites BYTES at OFFSET, all of them appended before (a header completed last).
  int overwrite(uint64_t offset, const void* data, size_t bytes);
  // Writes all that was appended, and waits for a sync asked for or under way (whose error it
  // returns: the file's next fsync may no longer report it). Appends may follow.
  int drain();

  uint64_t size() const { return written_ + used_; }
  // Bytes from offset 0 that a sync of this object's made durable.
  uint64_t synced() const {
    std::lock_guard lock(mutex_);
    return synced_;
  }
  bool direct() const { return direct_ >= 0; }  // false from the first refusal on

 private:
  static constexpr size_t kAlign = detail::kPageBytes;  // memory and file offsets of a direct write
  static constexpr size_t kBufferBytes = 1 << 20;       // a direct write's size; two buffers in all
  static constexpr uint64_t kSyncBytes = 8 << 20;       // written between two syncs

  int write_out(const unsigned char* data, size_t bytes, uint64_t offset);  // direct, else buffered
  int wait_idle();  // until the writer holds no buffer; its error
  void writer();
  void syncer();

  // Both buffers in one huge page: a store's every byte passes through them, and fresh 4 KB pages
  // cost more to touch first than to fill again (docs/METHOD.md, "Fresh memory").
  detail::HugeArray<unsigned char> block_;
  unsigned char* buffer(int i) const { return block_.get() + static_cast<size_t>(i) * kBufferBytes; }
  std::atomic<int> direct_;  // the writer thread may give it up
  int buffered_;
  int fill_ = 0;          // the buffer being filled
  size_t used_ = 0;       // bytes of it
  uint64_t written_ = 0;  // the file offset of its first byte: all before went to the writer

  mutable std::mutex mutex_;
  std::condition_variable changed_;
  int pending_ = -1;  // the buffer the writer holds, or -1
  uint64_t pending_offset_ = 0;
  size_t pending_bytes_ = 0;
  uint64_t on_disk_ = 0;      // bytes from offset 0 the writer has written
  uint64_t since_sync_ = 0;   // of them, written since a sync was last asked for
  uint64_t synced_ = 0;       // bytes from offset 0 a sync made durable
  bool sync_wanted_ = false;  // for the syncer thread
  bool syncing_ = false;
  int error_ = 0;
  bool stop_ = false;
  std::thread thread_;  // last: started once everything above is in place
  std::thread syncer_;
};

}  // namespace isotope
