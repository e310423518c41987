#pragma once
// Running a program as a child process and measuring it as a user would (isotope bench): its
// whole wall time and its own peak memory (wait4's rusage), with its output kept in a file; and
// dropping a file from the OS page cache, so that the next reader finds it cold.
#include <cstdint>
#include <string>
#include <vector>

namespace isotope::tools {

struct ChildRun {
  int code = -1;           // exit status; -1 when it did not exit normally or did not start
  double seconds = 0;      // wall time from spawn to exit
  int64_t max_rss_kb = 0;  // its own peak resident set
  std::string output;      // stdout and stderr
};

// Runs argv[0] (found on PATH when it has no '/') with ARGV, stdout and stderr into LOG (a path
// the caller removes), and waits for it. Never throws for the child's failure: see `code`.
ChildRun run_child(const std::vector<std::string>& argv, const std::string& log);

// From now on, run_child's children are spawned by a copy of this process made now (a fork that
// does nothing else), so that the peak memory reported is a child's own: the kernel's count for a
// child includes what the process it was spawned from held at that moment (a child is a copy of
// its parent until its exec), which for a benchmark holding a volume and a hierarchy was hundreds
// of MB more than the child ever used. Call it while this process is small; a no-op where it has
// more than one thread already (a fork would copy their locks in any state) or where called
// before. The copy ends when this process does.
void spawn_children_from_here();

// The path of this process's own executable (/proc/self/exe).
std::string self_executable();

// Writes back and drops FILE's pages from the page cache (posix_fadvise DONTNEED; no privilege
// needed), so that the next read of it comes from the disk. Best effort: false when it could not.
bool evict_from_page_cache(const std::string& file);

}  // namespace isotope::tools
