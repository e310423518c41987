#pragma once
// Scratch lent from task to task: a task takes an object and gives it back when done, so the next
// task reuses memory already touched, and there are never more objects than tasks run at once.
// On the reference machine fresh memory costs more than the work that fills it (docs/METHOD.md,
// "In parallel"). A mutex, not per-thread storage: two lock operations a task, and
// ThreadSanitizer sees them (oneTBB's thread-local storage is not instrumented, which is why
// parallel_for runs std::threads under it).
#include <cstddef>
#include <memory>
#include <mutex>
#include <utility>
#include <vector>

namespace isotope {

template <class T>
class LendingPool {
 public:
  // A lent object, or make() when none is free.
  template <class Make>
  std::unique_ptr<T> take(const Make& make) {
    {
      const std::lock_guard<std::mutex> lock(mutex_);
      if (!free_.empty()) {
        std::unique_ptr<T> t = std::move(free_.back());
        free_.pop_back();
        return t;
      }
    }
    return make();
  }
  void give(std::unique_ptr<T> t) {
    const std::lock_guard<std::mutex> lock(mutex_);
    free_.push_back(std::move(t));
  }
  // Lets go of the objects given back: their memory, once the tasks are done.
  void clear() {
    const std::lock_guard<std::mutex> lock(mutex_);
    free_.clear();
  }
  // Keeps, of the objects given back, the first whose BYTES_OF add up to at most BYTES; lets go of
  // the rest. Returns the bytes kept.
  template <class BytesOf>
  size_t keep_at_most(size_t bytes, const BytesOf& bytes_of) {
    const std::lock_guard<std::mutex> lock(mutex_);
    size_t kept = 0, n = 0;
    for (; n < free_.size(); ++n) {
      const size_t b = bytes_of(*free_[n]);
      if (b > bytes - kept) break;
      kept += b;
    }
    free_.resize(n);
    return kept;
  }

 private:
  std::mutex mutex_;
  std::vector<std::unique_ptr<T>> free_;
};

}  // namespace isotope
