#pragma once
// Scratch lent from task to task: a task takes an object and gives it back when done, so the next
// task reuses memory already touched, and there are never more objects than tasks run at once.
// On the reference machine fresh memory costs more than the work that fills it (docs/METHOD.md,
// "In parallel"). A mutex, not per-thread storage: two lock operations a task, and
// ThreadSanitizer sees them (oneTBB's thread-local storage is not instrumented,
// engine/core/parallel.h).
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

 private:
  std::mutex mutex_;
  std::vector<std::unique_ptr<T>> free_;
};

}  // namespace isotope
