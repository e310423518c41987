#pragma once
// The whole pages of a file's regions written past the page cache (O_DIRECT) by a thread of their
// own, from its buffers that the callers filled, while the callers go on encoding the next pieces
// (AtomicFile::write_region, fill_region). A direct write holds the thread that makes it until the
// disk has the bytes: made by the thread that encoded the piece, it kept that thread from
// encoding the next (docs/METHOD.md, "Reading and writing files").
#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <mutex>
#include <thread>
#include <vector>

#include "engine/core/huge_blocks.h"

namespace isotope {

class RegionWrites {
 public:
  // DIRECT: the file opened with O_DIRECT; BUFFERED: the same file without it (a piece the disk
  // refuses direct goes there, as every one after it). Neither is closed here. Throws
  // std::bad_alloc without memory for the buffers, std::system_error when no thread can start.
  RegionWrites(int direct, int buffered, size_t piece_bytes);
  ~RegionWrites();  // waits for the write under way, drops those not started and any error
  RegionWrites(const RegionWrites&) = delete;
  RegionWrites& operator=(const RegionWrites&) = delete;

  // A free buffer of piece_bytes and a page, page-aligned; waits for one. Null when a write failed
  // (`error` says which).
  unsigned char* take(int& error);
  // Hands BUFFER (from take) over: its BYTES at FROM (page-aligned, within it) go to OFFSET.
  void submit(unsigned char* buffer, const unsigned char* from, size_t bytes, uint64_t offset);
  void give_back(unsigned char* buffer);  // taken, and not handed over
  bool direct() const;                    // false from the first refusal on
  // Waits for every write handed over; 0, or the errno of the first that failed (the writes
  // handed over after it are dropped), as often as it is asked.
  int drain();

 private:
  struct Job {
    unsigned char* buffer;
    const unsigned char* from;
    size_t bytes;
    uint64_t offset;
  };
  void run();

  const int direct_, buffered_;
  const size_t stride_;
  detail::HugeArray<unsigned char> block_;
  mutable std::mutex mutex_;
  std::condition_variable changed_;
  std::vector<unsigned char*> free_;
  std::vector<Job> jobs_;  // room for every buffer reserved: submit() allocates nothing
  size_t busy_ = 0;        // jobs taken by the thread, not finished
  int error_ = 0;
  bool direct_refused_ = false, stop_ = false;
  std::thread thread_;
};

}  // namespace isotope
