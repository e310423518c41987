// Child processes as the benchmark measures them (run_child, evict_from_page_cache).
#include "tools/support/child_run.h"

#include <gtest/gtest.h>

#include <cstddef>
#include <string>
#include <vector>

#include "tests/support/temp_dir_test.h"

namespace isotope::tools {
namespace {

using ChildRunTest = testing::TempDirTest;

// A child spawned by a process that holds 512 MB reports its own peak memory, a few MB, where the
// kernel's count for a child spawned straight from that process starts at what the process held.
// Its output and exit status come back as before, and a program that does not exist did not run.
TEST_F(ChildRunTest, AChildsPeakMemoryIsItsOwnNotWhatItsParentHeld) {
  spawn_children_from_here();  // while this process is small, on one thread
  std::vector<char> held(size_t{512} << 20, 1);
  const ChildRun r = run_child({"/bin/sh", "-c", "echo ran; exit 3"}, path("log"));
  EXPECT_EQ(r.code, 3);
  EXPECT_EQ(r.output, "ran\n");
  EXPECT_GT(r.seconds, 0);
  EXPECT_GT(r.max_rss_kb, 0);
  // Below what the parent held by far, with room for a sanitizer's own memory in the copy that spawned it.
  EXPECT_LT(r.max_rss_kb, 192 << 10) << "the child's peak counts the 512 MB its parent held";
  EXPECT_EQ(run_child({path("missing")}, path("log")).code, -1);
  EXPECT_EQ(held[12345], 1);
}

}  // namespace
}  // namespace isotope::tools
