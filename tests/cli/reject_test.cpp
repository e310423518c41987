// The golden reject files (written by their generator script): bad volumes and
// stores, corrupted by kind, some under recomputed checksums. For every command that each file's
// NAME.expect lists, `isotope COMMAND FILE` must exit 1 with "isotope: error: " and the expected
// part of the message, write nothing, and leave the file as it was. docs/RELIABILITY.md lists them.
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "tools/support/child_run.h"

namespace isotope {
namespace {

namespace fs = std::filesystem;
const fs::path kRejects = fs::path(ISOTOPE_SOURCE_DIR) / "tests" / "golden";

std::vector<std::string> reject_files() {
  std::vector<std::string> names;
  for (const auto& e : fs::directory_iterator(kRejects))
    if (e.path().extension() == ".expect") names.push_back(e.path().stem().string());
  std::sort(names.begin(), names.end());
  return names;
}

std::string slurp(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

class Reject : public ::testing::TestWithParam<std::string> {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("isotope_reject_" + std::to_string(::getpid()));
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override {
    std::error_code ec;
    fs::remove_all(dir_, ec);
  }
  std::string path(const std::string& name) const { return (dir_ / name).string(); }
  fs::path dir_;
};

TEST(RejectFiles, ThereAreEnoughOfThemToMeanSomething) {
  // A folder emptied by mistake would otherwise pass as "every file rejected".
  EXPECT_GE(reject_files().size(), 30u);
}

TEST_P(Reject, GivesItsMessageExitsOneAndWritesNothing) {
  const std::string name = GetParam();
  const std::string expect = slurp(kRejects / (name + ".expect"));
  ASSERT_FALSE(expect.empty()) << name << ".expect is empty";
  // A copy in a folder of its own: what the command writes (or leaves) there is all it wrote.
  const fs::path dir = fs::path(path("in"));
  fs::create_directory(dir);
  const fs::path input = dir / name;
  fs::copy_file(kRejects / name, input);
  const std::string bytes = slurp(input);
  size_t lines = 0;
  std::istringstream in(expect);
  for (std::string line; std::getline(in, line);) {
    if (line.empty()) continue;
    const size_t colon = line.find(": ");
    ASSERT_NE(colon, std::string::npos) << name << ".expect: " << line;
    const std::string command = line.substr(0, colon), message = line.substr(colon + 2);
    std::vector<std::string> argv = {ISOTOPE_BINARY, command, input.string()};
    if (command == "extract") argv.insert(argv.end(), {"--iso", "0.5", "-o", (dir / "out.ply").string()});
    const tools::ChildRun r = tools::run_child(argv, path("log"));
    EXPECT_EQ(r.code, 1) << name << " " << command << ": " << r.output;
    EXPECT_NE(r.output.find("isotope: error: "), std::string::npos) << r.output;
    EXPECT_NE(r.output.find(message), std::string::npos)
        << name << " " << command << ": expected '" << message << "' in: " << r.output;
    std::set<std::string> left;
    for (const auto& e : fs::directory_iterator(dir)) left.insert(e.path().filename().string());
    EXPECT_EQ(left, std::set<std::string>{name}) << command << " wrote into the input's folder";
    EXPECT_EQ(slurp(input), bytes) << command << " changed its input";
    ++lines;
  }
  EXPECT_GT(lines, 0u);
}

INSTANTIATE_TEST_SUITE_P(Golden, Reject, ::testing::ValuesIn(reject_files()), [](const auto& param_info) {
  std::string id;
  for (char c : param_info.param) id += std::isalnum(static_cast<unsigned char>(c)) ? c : '_';
  return id;
});

}  // namespace
}  // namespace isotope
