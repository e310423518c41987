#pragma once
// Progress of a long engine step, for a user watching a terminal. Workers call advance() from
// any thread; the callback sees a fraction that only grows, at most once per percent, one call
// at a time. No callback, no cost beyond one relaxed atomic add per call.
#include <atomic>
#include <cstdint>
#include <mutex>

#include "isotope/progress.h"

namespace isotope {

class ProgressReporter {
 public:
  ProgressReporter(ProgressCallback callback, int64_t total) : callback_(std::move(callback)), total_(total) {}

  void advance(int64_t work) {
    if (!callback_ || total_ <= 0) return;
    const int64_t done = done_.fetch_add(work, std::memory_order_relaxed) + work;
    const int percent = static_cast<int>(100 * done / total_);
    if (percent <= reported_.load(std::memory_order_relaxed)) return;
    std::lock_guard<std::mutex> lock(mutex_);
    if (percent <= reported_.load(std::memory_order_relaxed)) return;
    reported_.store(percent, std::memory_order_relaxed);
    callback_(percent >= 100 ? 1.0 : percent / 100.0);
  }

 private:
  ProgressCallback callback_;
  int64_t total_;
  std::atomic<int64_t> done_{0};
  std::atomic<int> reported_{-1};
  std::mutex mutex_;
};

}  // namespace isotope
