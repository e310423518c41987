#pragma once
// Ctrl-C (SIGINT) and SIGTERM as a request to stop: while a guard is installed they only raise a
// flag, which long work polls between steps and answers by throwing, so that destructors remove
// temporary files (a convert's partial output, isotope bench's stores).
#include <atomic>

namespace isotope::tools {

class InterruptGuard {
 public:
  InterruptGuard();  // clears the flag
  ~InterruptGuard();
  InterruptGuard(const InterruptGuard&) = delete;
  InterruptGuard& operator=(const InterruptGuard&) = delete;

  static const std::atomic<bool>& flag();  // e.g. RunContext::cancel
  static bool interrupted() { return flag().load(); }

 private:
  void (*int_)(int);
  void (*term_)(int);
};

}  // namespace isotope::tools
