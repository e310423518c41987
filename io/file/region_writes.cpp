#include "io/file/region_writes.h"

#include <cerrno>

#include "io/file/positioned_io.h"

namespace isotope {
namespace {

// One buffer being written while another is filled: more measured no faster (a third and a
// fourth, embryo's and noise 513^3's meshes; docs/METHOD.md, "Reading and writing files").
constexpr size_t kBuffers = 2;

}  // namespace

RegionWrites::RegionWrites(int direct, int buffered, size_t piece_bytes)
    : direct_(direct), buffered_(buffered), stride_(piece_bytes + detail::kPageBytes) {
  block_ = detail::make_huge_array<unsigned char>(kBuffers * stride_);
  for (size_t i = 0; i < kBuffers; ++i) free_.push_back(block_.get() + i * stride_);
  jobs_.reserve(kBuffers);
  thread_ = std::thread([this] { run(); });
}

RegionWrites::~RegionWrites() {
  {
    std::lock_guard lock(mutex_);
    jobs_.clear();  // a file given up: what is not written yet never will be
    stop_ = true;
  }
  changed_.notify_all();
  thread_.join();
}

unsigned char* RegionWrites::take(int& error) {
  std::unique_lock lock(mutex_);
  changed_.wait(lock, [&] { return error_ != 0 || !free_.empty(); });
  error = error_;
  if (error_ != 0) return nullptr;
  unsigned char* buffer = free_.back();
  free_.pop_back();
  return buffer;
}

void RegionWrites::submit(unsigned char* buffer, const unsigned char* from, size_t bytes, uint64_t offset) {
  {
    std::lock_guard lock(mutex_);
    jobs_.push_back({buffer, from, bytes, offset});
  }
  changed_.notify_all();
}

void RegionWrites::give_back(unsigned char* buffer) {
  {
    std::lock_guard lock(mutex_);
    free_.push_back(buffer);
  }
  changed_.notify_all();
}

bool RegionWrites::direct() const {
  std::lock_guard lock(mutex_);
  return !direct_refused_;
}

int RegionWrites::drain() {
  std::unique_lock lock(mutex_);
  changed_.wait(lock, [&] { return jobs_.empty() && busy_ == 0; });
  return error_;
}

void RegionWrites::run() {
  std::unique_lock lock(mutex_);
  for (;;) {
    changed_.wait(lock, [&] { return stop_ || !jobs_.empty(); });
    if (jobs_.empty()) return;
    const Job job = jobs_.front();
    jobs_.erase(jobs_.begin());
    ++busy_;
    const bool skip = error_ != 0, direct = !direct_refused_;
    lock.unlock();
    int err = 0;
    bool refused = false;
    if (!skip) {  // after a failure the file means nothing: the rest is dropped
      if (direct) {
        err = pwrite_all(direct_, job.from, job.bytes, job.offset);
        // EINVAL: a file system or device that takes no such write (or wants another alignment):
        // the same bytes through the page cache, and every piece after it.
        refused = err == EINVAL;
      }
      if (!direct || refused) err = pwrite_all(buffered_, job.from, job.bytes, job.offset);
    }
    lock.lock();
    if (refused) direct_refused_ = true;
    if (err != 0 && error_ == 0) error_ = err;
    free_.push_back(job.buffer);
    --busy_;
    changed_.notify_all();
  }
}

}  // namespace isotope
