// `isotope convert` keeps its memory within --memory-mb whatever the volume's size: a volume
// more than 8 times the budget converts with a peak resident set under the budget plus what the
// process needs for a tiny volume, and the store it writes does not depend on the budget.
// Each isotope run is a child process, so that its peak RSS is its own (wait4's rusage): not the
// generator's, nor this test's.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <spawn.h>
#include <sys/resource.h>
#include <sys/wait.h>

#include <algorithm>
#include <chrono>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <iterator>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "tests/support/child_process.h"
#include "tests/support/temp_dir_test.h"

namespace isotope {
namespace {

namespace fs = std::filesystem;

constexpr int64_t kBudgetMb = 32;
constexpr int64_t kSize = 513;  // the case the budget is held to: 513^3 uint16 = 270 MB, over 8 times the budget
// Slack above the tiny convert's peak: allocator arenas and page-granular growth that vary run to run.
constexpr int64_t kMarginMb = 8;

using testing::Child;
using testing::report;
using testing::run_isotope;
using testing::same_bytes;
using testing::slurp;

class ConvertMemory : public testing::TempDirTest {
 protected:
  // Runs isotope ARGS and expects exit 0, showing its output otherwise.
  Child expect_ok(const std::vector<std::string>& args) {
    const std::string log = path("log.txt");
    const Child c = run_isotope(args, log);
    EXPECT_EQ(c.code, 0) << args.front() << ": " << slurp(log);
    return c;
  }
};

TEST_F(ConvertMemory, VolumeEightTimesTheBudgetConvertsWithinItAndTheStoreIgnoresTheBudget) {
  const std::string budget = std::to_string(kBudgetMb), side = std::to_string(kSize);
  const std::string big = path("alg_" + side + "x" + side + "x" + side + "_uint16.raw");
  const std::string tiny = path("sphere_9x9x9_uint16.raw");
  // The algebraic field is smooth away from its singular point, and 10x faster to sample at
  // 513^3 than the noise field's sum of Gaussians.
  expect_ok({"generate", "algebraic", "--size", side, "--type", "uint16", "-q", "-o", big});
  expect_ok({"generate", "sphere", "--size", "9", "--type", "uint16", "-q", "-o", tiny});
  ASSERT_GE(static_cast<int64_t>(fs::file_size(big)), 8 * (kBudgetMb << 20));

  // What the process needs whatever the volume: binary, libraries, thread pool, zstd contexts.
  const Child baseline = expect_ok({"convert", tiny, path("tiny.isotope"), "--memory-mb", budget, "-q"});
  const Child convert = expect_ok({"convert", big, path("big.isotope"), "--memory-mb", budget, "-q"});
  const int64_t limit_kb = (kBudgetMb + kMarginMb) * 1024 + baseline.max_rss_kb;
  report("budget_mb", static_cast<double>(kBudgetMb));
  report("input_mb", static_cast<double>(fs::file_size(big)) / (1 << 20));
  report("baseline_rss_mb", static_cast<double>(baseline.max_rss_kb) / 1024);
  report("convert_rss_mb", static_cast<double>(convert.max_rss_kb) / 1024);
  report("limit_rss_mb", static_cast<double>(limit_kb) / 1024);
  report("convert_seconds", convert.seconds);
  EXPECT_LT(convert.max_rss_kb, limit_kb);

  const Child verify = expect_ok({"verify", path("big.isotope"), "-q"});
  report("verify_seconds", verify.seconds);
  const std::string info = path("info.json");
  ASSERT_EQ(run_isotope({"info", path("big.isotope"), "--json"}, info).code, 0) << slurp(info);
  const double ratio = nlohmann::json::parse(slurp(info)).at("size_ratio").get<double>();
  report("size_ratio", ratio);
  EXPECT_LE(ratio, 1.5);

  const Child roomy = expect_ok({"convert", big, path("roomy.isotope"), "--memory-mb", "1024", "-q"});
  report("convert_1024mb_rss_mb", static_cast<double>(roomy.max_rss_kb) / 1024);
  report("convert_1024mb_seconds", roomy.seconds);
  EXPECT_TRUE(same_bytes(path("big.isotope"), path("roomy.isotope")))
      << "the store written with --memory-mb " << kBudgetMb << " differs from the one written with 1024";
}

// A band's hand-over that fits the budget is kept in scratch files too (through the page cache),
// not in the process's memory: a 257^3 volume, whose hand-over to band 1 is 129^3 entries of 48
// bytes (103 MB, under a quarter of the default budget), converts with a peak resident set well
// under that above the tiny volume's (about 31 MB; 140 MB with the hand-over in memory), and
// the store is the one a budget too small for the hand-over writes.
TEST_F(ConvertMemory, AHandOverThatFitsTheBudgetStaysOutOfTheProcesssMemory) {
  const std::string volume = path("alg_257x257x257_uint8.raw");
  const std::string tiny = path("sphere_9x9x9_uint8.raw");
  expect_ok({"generate", "algebraic", "--size", "257", "--type", "uint8", "-q", "-o", volume});
  expect_ok({"generate", "sphere", "--size", "9", "--type", "uint8", "-q", "-o", tiny});
  const Child baseline = expect_ok({"convert", tiny, path("tiny.isotope"), "-q"});
  const Child convert = expect_ok({"convert", volume, path("roomy.isotope"), "-q"});
  const int64_t handover_mb = 129 * 129 * 129 * 48 >> 20;
  report("handover_mb", static_cast<double>(handover_mb));
  report("baseline_rss_mb", static_cast<double>(baseline.max_rss_kb) / 1024);
  report("convert_rss_mb", static_cast<double>(convert.max_rss_kb) / 1024);
  EXPECT_LT(convert.max_rss_kb - baseline.max_rss_kb, handover_mb / 2 * 1024);
  expect_ok({"convert", volume, path("tight.isotope"), "--memory-mb", "16", "-q"});
  EXPECT_TRUE(same_bytes(path("roomy.isotope"), path("tight.isotope")));
}

}  // namespace
}  // namespace isotope
