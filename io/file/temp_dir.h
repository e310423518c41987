#pragma once
// A folder made for one run and removed, with everything in it, when destroyed (however the scope
// ends): the stores of isotope bench, the inputs of the benchmark suite.
#include <filesystem>
#include <system_error>

namespace isotope {

class TempDir {
 public:
  explicit TempDir(std::filesystem::path path) : path_(std::move(path)) { std::filesystem::create_directories(path_); }
  ~TempDir() {
    std::error_code ignored;
    std::filesystem::remove_all(path_, ignored);
  }
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;
  const std::filesystem::path& path() const { return path_; }

 private:
  std::filesystem::path path_;
};

}  // namespace isotope
