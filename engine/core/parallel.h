#pragma once
// The one place that runs the engine's loops in parallel. oneTBB normally;
// plain std::threads when built for ThreadSanitizer (ISOTOPE_STD_THREADS), because Debian's
// libtbb is not instrumented and TSan would report TBB's own task hand-offs as races, hiding
// any of ours. Both honour tbb::global_control's max_allowed_parallelism, so one thread runs
// the same body serially.
#include <tbb/global_control.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <exception>
#include <mutex>
#include <optional>
#include <thread>
#include <vector>

namespace isotope {

// The threads the engine's loops may run on: tbb::global_control's max_allowed_parallelism, which
// a face sets from its --threads.
inline int64_t thread_count() {
  return static_cast<int64_t>(tbb::global_control::active_value(tbb::global_control::max_allowed_parallelism));
}

// RunContext::threads for the span of a call: the process's max_allowed_parallelism while it
// lives, when threads > 0 (0 leaves the process's own limit, such as a face's --threads).
class ThreadLimit {
 public:
  explicit ThreadLimit(int threads) {
    if (threads > 0) control_.emplace(tbb::global_control::max_allowed_parallelism, static_cast<size_t>(threads));
  }

 private:
  std::optional<tbb::global_control> control_;
};

// Whether parallel_for(begin, end, ...) calls its bodies one after the other on the calling
// thread: one thread allowed, or at most one index. A body may then skip what guards it against
// the others (locked adds).
inline bool runs_serially(int64_t begin, int64_t end) { return thread_count() <= 1 || end - begin <= 1; }

// Calls body(i) for every i in [begin, end), in any order, possibly concurrently.
template <class Body>
void parallel_for(int64_t begin, int64_t end, const Body& body) {
  if (runs_serially(begin, end)) {
    for (int64_t i = begin; i < end; ++i) body(i);
    return;
  }
#ifdef ISOTOPE_STD_THREADS
  std::vector<std::thread> pool;
  const int64_t count = std::min(thread_count(), end - begin);
  std::mutex mutex;
  std::exception_ptr first;  // rethrown after the join, as tbb::parallel_for does
  for (int64_t t = 0; t < count; ++t)
    pool.emplace_back([&, t] {
      try {
        for (int64_t i = begin + t; i < end; i += count) body(i);
      } catch (...) {
        const std::lock_guard<std::mutex> lock(mutex);
        if (!first) first = std::current_exception();
      }
    });
  for (std::thread& th : pool) th.join();
  if (first) std::rethrow_exception(first);
#else
  tbb::parallel_for(begin, end, body);
#endif
}

// Calls body(i) for every i in [begin, end), possibly concurrently, handing the indices out one
// at a time in increasing order: the bodies running at any moment have neighbouring indices.
// For work items in a spatial order (the traversal's pieces) that share data with their
// neighbours, e.g. bricks in a cache of bounded size. Once a body throws, no index is handed out
// again (bodies running go on to their end), and the first exception is rethrown.
template <class Body>
void parallel_for_in_order(int64_t begin, int64_t end, const Body& body) {
  const int64_t threads = thread_count();
  std::atomic<int64_t> next{begin};
  parallel_for(int64_t{0}, std::min(threads, std::max<int64_t>(end - begin, 1)), [&](int64_t) {
    for (int64_t i = next++; i < end; i = next++) {
      try {
        body(i);
      } catch (...) {
        next = end;
        throw;
      }
    }
  });
}

// Runs F so that while it waits for parallel work of its own, its thread runs only that work, not
// a task of the caller's, which could wait for what F's caller holds (a lock, a commit).
template <class F>
void isolated(const F& f) {
#ifdef ISOTOPE_STD_THREADS
  f();  // a plain thread waits for its own threads only
#else
  tbb::this_task_arena::isolate(f);
#endif
}

// Calls build(i) for every i in [begin, end), possibly concurrently, handed out in increasing
// order, and commit(i) for every i in increasing order, one at a time, as soon as build(i) and
// every commit before it are done: on the thread whose build completed the run, which goes on
// committing while the next ones are built. The lock is not held during a commit, so that a build
// done meanwhile is only noted, and its thread builds on. build(i) starts only once i - window is
// committed, so that it may use slot (i - begin) % window and at most `window` results wait at
// once. Unlike batches of `window` builds, a long build holds up only the commits after it, not the
// builds. Once a build or a commit throws, no build or commit starts again (those running go on to
// their end), and the first exception is rethrown.
template <class Build, class Commit>
void parallel_in_order_committed(int64_t begin, int64_t end, int64_t window, const Build& build, const Commit& commit) {
  std::mutex mutex;
  std::condition_variable freed;
  int64_t committed = begin;  // [begin, committed) committed
  std::vector<char> built(static_cast<size_t>(std::max<int64_t>(window, 1)), 0);
  bool failed = false;
  bool committing = false;  // a thread is committing: it takes up what is built meanwhile
  parallel_for_in_order(begin, end, [&](int64_t i) {
    const auto slot = static_cast<size_t>((i - begin) % window);
    {
      std::unique_lock<std::mutex> lock(mutex);
      freed.wait(lock, [&] { return failed || i < committed + window; });
      if (failed) return;
    }
    bool commits = false;  // this thread is the one committing
    try {
      // A build taken up while this one waits for parallel work of its own would wait for a
      // commit that waits for this build.
      isolated([&] { build(i); });
      std::unique_lock<std::mutex> lock(mutex);
      built[slot] = 1;
      if (committing) return;
      committing = commits = true;
      for (size_t next = static_cast<size_t>((committed - begin) % window); !failed && committed < end && built[next];
           next = static_cast<size_t>((committed - begin) % window)) {
        built[next] = 0;
        const int64_t c = committed;
        lock.unlock();
        commit(c);
        lock.lock();
        ++committed;
        freed.notify_all();
      }
      committing = false;
    } catch (...) {
      const std::lock_guard<std::mutex> lock(mutex);
      failed = true;
      if (commits) committing = false;
      freed.notify_all();
      throw;
    }
  });
}

}  // namespace isotope
