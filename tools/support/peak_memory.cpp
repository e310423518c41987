// Peak resident memory (peak_rss_bytes, reset_peak_rss).
#include "tools/support/peak_memory.h"

#include <sys/resource.h>

#include <cstdio>
#include <cstring>

namespace isotope::tools {

bool reset_peak_rss() {
  std::FILE* f = std::fopen("/proc/self/clear_refs", "w");
  if (!f) return false;
  const bool written = std::fputs("5", f) >= 0;  // 5: reset the peak RSS (proc(5))
  return std::fclose(f) == 0 && written;
}

uint64_t peak_rss_bytes() {
  if (std::FILE* f = std::fopen("/proc/self/status", "r")) {
    char line[256];
    unsigned long long kib = 0;
    bool found = false;
    while (!found && std::fgets(line, sizeof line, f)) found = std::sscanf(line, "VmHWM: %llu kB", &kib) == 1;
    std::fclose(f);
    if (found) return static_cast<uint64_t>(kib) << 10;
  }
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  return static_cast<uint64_t>(usage.ru_maxrss) << 10;  // KiB on Linux
}

}  // namespace isotope::tools
