#pragma once
// What the benchmark files share.
#include <benchmark/benchmark.h>

#include <exception>

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

}  // namespace isotope::bench
