#include "io/file/direct_appends.h"

#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>

#include "io/file/positioned_io.h"

namespace isotope {

DirectAppends::DirectAppends(int direct, int buffered)
    : block_(detail::make_huge_array<unsigned char>(2 * kBufferBytes)), direct_(direct), buffered_(buffered) {
  thread_ = std::thread([this] { writer(); });
  try {
    syncer_ = std::thread([this] { syncer(); });
  } catch (...) {
    {
      std::lock_guard lock(mutex_);
      stop_ = true;
    }
    changed_.notify_all();
    thread_.join();
    throw;
  }
}

DirectAppends::~DirectAppends() {
  {
    std::lock_guard lock(mutex_);
    stop_ = true;
  }
  changed_.notify_all();
  thread_.join();
  syncer_.join();
}

int DirectAppends::write_out(const unsigned char* data, size_t bytes, uint64_t offset) {
  if (direct_ >= 0 && offset % kAlign == 0 && bytes % kAlign == 0) {
    const int err = pwrite_all(direct_, data, bytes, offset);
    if (err != EINVAL) return err;
    direct_ = -1;  // refused (not a short write's unaligned rest: that fails again below, as it should)
  }
  return pwrite_all(buffered_, data, bytes, offset);
}

void DirectAppends::writer() {
  std::unique_lock lock(mutex_);
  for (;;) {
    changed_.wait(lock, [&] { return pending_ >= 0 || stop_; });
    if (pending_ < 0) return;  // stopped, nothing held
    const unsigned char* data = buffer(pending_);
    const uint64_t offset = pending_offset_;
    const size_t bytes = pending_bytes_;
    lock.unlock();
    const int err = write_out(data, bytes, offset);
    lock.lock();
    if (err != 0 && error_ == 0) error_ = err;
    if (err == 0) {
      on_disk_ = offset + bytes;
      since_sync_ += bytes;
      if (since_sync_ >= kSyncBytes) sync_wanted_ = true, since_sync_ = 0;
    }
    pending_ = -1;
    changed_.notify_all();
  }
}

void DirectAppends::syncer() {
  std::unique_lock lock(mutex_);
  for (;;) {
    changed_.wait(lock, [&] { return sync_wanted_ || stop_; });
    if (stop_) return;
    sync_wanted_ = false;
    syncing_ = true;
    const uint64_t upto = on_disk_;  // writes completed before the sync starts: it covers them
    lock.unlock();
    // The buffered descriptor: the same file, and there even where direct writes were refused.
    const int err = ::fdatasync(buffered_) == 0 ? 0 : errno;
    lock.lock();
    syncing_ = false;
    if (err != 0 && error_ == 0) error_ = err;
    if (err == 0) synced_ = std::max(synced_, upto);
    changed_.notify_all();
  }
}

int DirectAppends::wait_idle() {
  std::unique_lock lock(mutex_);
  changed_.wait(lock, [&] { return pending_ < 0; });
  return error_;
}

int DirectAppends::append(const void* data, size_t bytes) {
  const auto* p = static_cast<const unsigned char*>(data);
  while (bytes > 0) {
    const size_t piece = std::min(bytes, kBufferBytes - used_);
    std::memcpy(buffer(fill_) + used_, p, piece);
    used_ += piece, p += piece, bytes -= piece;
    if (used_ < kBufferBytes) break;
    // Full: to the writer, once it is done with the other buffer, which this one then becomes.
    {
      std::unique_lock lock(mutex_);
      changed_.wait(lock, [&] { return pending_ < 0; });
      if (error_ != 0) return error_;
      pending_ = fill_;
      pending_offset_ = written_;
      pending_bytes_ = used_;
    }
    changed_.notify_all();
    fill_ ^= 1;
    written_ += used_;
    used_ = 0;
  }
  return 0;
}

int DirectAppends::overwrite(uint64_t offset, const void* data, size_t bytes) {
  const auto* p = static_cast<const unsigned char*>(data);
  if (offset < written_) {  // on disk or on its way: once the writer is done, through the page cache
    if (const int err = wait_idle()) return err;
    const size_t before = static_cast<size_t>(std::min<uint64_t>(bytes, written_ - offset));
    if (const int err = pwrite_all(buffered_, p, before, offset)) return err;
    p += before, offset += before, bytes -= before;
  }
  if (bytes > 0) std::memcpy(buffer(fill_) + (offset - written_), p, bytes);
  return 0;
}

int DirectAppends::drain() {
  if (const int err = wait_idle()) return err;
  const unsigned char* data = buffer(fill_);
  const size_t whole = used_ / kAlign * kAlign;
  if (const int err = write_out(data, whole, written_)) return err;
  if (const int err = pwrite_all(buffered_, data + whole, used_ - whole, written_ + whole)) return err;
  written_ += used_;
  used_ = 0;
  // The sync asked for or under way is waited for (no other starts until more is appended): an
  // error it met is returned here, as the file's fsync, on the same open file, would no longer
  // report it.
  std::unique_lock lock(mutex_);
  changed_.wait(lock, [&] { return !syncing_ && !sync_wanted_; });
  return error_;
}

}  // namespace isotope
