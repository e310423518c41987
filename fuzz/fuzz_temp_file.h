#pragma once
// The readers under fuzz take paths (as isotope's commands do): each input is written to one file
// per process, in the temporary folder, and read back from there.
#include <fcntl.h>
#include <unistd.h>

#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <string>

namespace isotope::fuzz {

inline std::string temp_path(const std::string& suffix) {
  const char* dir = std::getenv("TMPDIR");
  return std::string(dir != nullptr && *dir != 0 ? dir : "/tmp") + "/isotope-fuzz-" + std::to_string(::getpid()) +
         suffix;
}

inline void write_whole(const std::string& path, const uint8_t* data, size_t size) {
  const int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0600);
  if (fd < 0) std::abort();  // the harness itself failed: not a finding
  while (size > 0) {
    const ssize_t n = ::write(fd, data, size);
    if (n <= 0) std::abort();
    data += n, size -= static_cast<size_t>(n);
  }
  ::close(fd);
}

// The one input file of a process, removed when the process ends.
struct RemoveAtExit {
  std::string path;
  ~RemoveAtExit() { std::filesystem::remove(path); }
};

}  // namespace isotope::fuzz
