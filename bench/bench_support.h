#pragma once
// What the benchmark files share.
#include <benchmark/benchmark.h>
#include <unistd.h>

#include <algorithm>
#include <exception>
#include <filesystem>
#include <string>
#include <system_error>
#include <thread>
#include <vector>

#include "io/file/temp_dir.h"

namespace isotope::bench {

// Runs SETUP, reporting a failure (missing data file, engine or I/O error) as a skipped
// benchmark: an exception must not escape into the benchmark runner.
template <class Setup>
bool prepare(benchmark::State& state, Setup setup) {
  try {
    setup();
    return true;
  } catch (const std::exception& e) {
    state.SkipWithError(e.what());
    return false;
  }
}

// The oneTBB thread caps a scaling series runs at: 1, 2, 4, ... below the machine's core count,
// then the core count itself. Doubling keeps the series short on a big machine (7 entries on
// 64 cores) while still showing where scaling bends.
inline std::vector<int> thread_counts() {
  const int all = static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  std::vector<int> counts;
  for (int n = 1; n < all; n *= 2) counts.push_back(n);
  counts.push_back(all);
  return counts;
}

// $TMPDIR/isotope_bench_<NAME>.<pid>: held as a TempDir in a function-local static, it lasts
// until the process exits.
inline std::filesystem::path process_temp_path(const std::string& name) {
  return std::filesystem::temp_directory_path() / ("isotope_bench_" + name + "." + std::to_string(::getpid()));
}

}  // namespace isotope::bench
