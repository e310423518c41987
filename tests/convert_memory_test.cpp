// `isotope convert` keeps its memory within --memory-mb whatever the volume's size: a volume
// more than 8 times the budget converts with a peak resident set under the budget plus what the
// process needs for a tiny volume, and the store it writes does not depend on the budget.
// Each isotope run is a child process, so that its peak RSS is its own (wait4's rusage): not the
// generator's, nor this test's.
#include <gtest/gtest.h>
#include <fcntl.h>
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

#include "tests/temp_dir_test.h"

extern char** environ;

namespace isotope {
namespace {

namespace fs = std::filesystem;

constexpr int64_t kBudgetMb = 32;
constexpr int64_t kSize = 513;  // the case: 513^3 uint16 = 270 MB, over 8 times the budget
// Slack above the tiny convert's peak: allocator arenas and page-granular growth that vary run to run.
constexpr int64_t kMarginMb = 8;

struct Child {
  int code = -1;
  int64_t max_rss_kb = 0;  // ru_maxrss, KB on Linux
  double seconds = 0;
};

// Runs the isotope binary with ARGS, stdout into OUT (stderr too), and waits for it alone.
Child run_isotope(const std::vector<std::string>& args, const std::string& out) {
  std::vector<std::string> argv_text = {ISOTOPE_BINARY};
  argv_text.insert(argv_text.end(), args.begin(), args.end());
  std::vector<char*> argv;
  for (std::string& a : argv_text) argv.push_back(a.data());
  argv.push_back(nullptr);

  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_addopen(&actions, 1, out.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  posix_spawn_file_actions_adddup2(&actions, 1, 2);
  const auto start = std::chrono::steady_clock::now();
  pid_t pid = -1;
  const int spawned = posix_spawn(&pid, argv[0], &actions, nullptr, argv.data(), environ);
  posix_spawn_file_actions_destroy(&actions);
  Child c;
  if (spawned != 0) {
    ADD_FAILURE() << "cannot start " << argv[0] << ": error " << spawned;
    return c;
  }
  int status = 0;
  rusage usage{};
  if (wait4(pid, &status, 0, &usage) != pid) {
    ADD_FAILURE() << "wait4 failed for " << argv[0];
    return c;
  }
  c.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  c.code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  c.max_rss_kb = usage.ru_maxrss;
  return c;
}

std::string slurp(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

// Compared block by block: the stores are 100+ MB each.
bool same_bytes(const std::string& a, const std::string& b) {
  if (fs::file_size(a) != fs::file_size(b)) return false;
  std::ifstream fa(a, std::ios::binary), fb(b, std::ios::binary);
  std::vector<char> ba(1 << 20), bb(1 << 20);
  while (fa && fb) {
    fa.read(ba.data(), static_cast<std::streamsize>(ba.size()));
    fb.read(bb.data(), static_cast<std::streamsize>(bb.size()));
    if (fa.gcount() != fb.gcount() || !std::equal(ba.begin(), ba.begin() + fa.gcount(), bb.begin())) return false;
  }
  return true;
}

void report(const std::string& key, double value) {
  ::testing::Test::RecordProperty(key, std::to_string(value));
  std::cout << "[ measured ] " << key << " = " << value << std::endl;
}

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

}  // namespace
}  // namespace isotope
