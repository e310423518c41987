#pragma once
// A fixture for tests that write files: a fresh, empty directory per test, removed afterwards.
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cstdlib>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

// TEXT is evaluated once (it may run something, like a verify); more can be streamed after it.
#define EXPECT_CONTAINS(text, part) EXPECT_TRUE(::isotope::testing::contains_text((text), (part)))

namespace isotope::testing {

inline ::testing::AssertionResult contains_text(const std::string& text, const std::string& part) {
  if (text.find(part) != std::string::npos) return ::testing::AssertionSuccess();
  return ::testing::AssertionFailure() << "'" << part << "' is not in the message: " << text;
}

class TempDirTest : public ::testing::Test {
 protected:
  void SetUp() override {
    static std::atomic<int> serial{0};
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    dir_ = std::filesystem::temp_directory_path() /
           ("isotope_" + std::string(info->test_suite_name()) + "_" + std::to_string(::getpid()) + "_" + info->name() +
            "_" + std::to_string(serial++));
    std::filesystem::remove_all(dir_);
    std::filesystem::create_directories(dir_);
  }
  void TearDown() override {
    std::error_code ec;
    std::filesystem::remove_all(dir_, ec);
  }
  std::string path(const std::string& name) const { return (dir_ / name).string(); }
  // The names in the directory, sorted: what a failed write must not leave behind.
  std::vector<std::string> entries() const {
    std::vector<std::string> names;
    for (const auto& e : std::filesystem::directory_iterator(dir_)) names.push_back(e.path().filename().string());
    std::sort(names.begin(), names.end());
    return names;
  }

  std::filesystem::path dir_;
};

// TMPDIR set to DIR for as long as it lives (inherited by the processes started meanwhile): where
// a source writes its hierarchy's store.
class TemporaryDirectoryIs {
 public:
  explicit TemporaryDirectoryIs(const std::string& dir) {
    if (const char* was = std::getenv("TMPDIR")) was_ = was;
    ::setenv("TMPDIR", dir.c_str(), 1);
  }
  ~TemporaryDirectoryIs() {
    if (was_)
      ::setenv("TMPDIR", was_->c_str(), 1);
    else
      ::unsetenv("TMPDIR");
  }
  TemporaryDirectoryIs(const TemporaryDirectoryIs&) = delete;
  TemporaryDirectoryIs& operator=(const TemporaryDirectoryIs&) = delete;

 private:
  std::optional<std::string> was_;
};

// A fresh folder in the working directory (the build tree, on a disk) for as long as it lives,
// removed with what it holds: for files whose writeback a test watches, which a temporary
// directory in memory (tmpfs) would never do.
class FolderOnDisk {
 public:
  explicit FolderOnDisk(const std::string& name)
      : path_((std::filesystem::current_path() / (name + "." + std::to_string(::getpid()))).string()) {
    std::filesystem::remove_all(path_);
    std::filesystem::create_directory(path_);
  }
  ~FolderOnDisk() {
    std::error_code ignored;
    std::filesystem::remove_all(path_, ignored);
  }
  FolderOnDisk(const FolderOnDisk&) = delete;
  FolderOnDisk& operator=(const FolderOnDisk&) = delete;
  const std::string& path() const { return path_; }

 private:
  std::string path_;
};

}  // namespace isotope::testing
