#pragma once
// The benchmark suite `isotope bench` runs (its definition beside this header): the product timed as a
// user meets it on a fixed set of volumes, beside full-resolution marching tetrahedra and the
// peers, with the performance targets met or missed row by row. The Google Benchmark binaries
// time the same engine paths stage by stage.
#include <cstdint>
#include <string>
#include <vector>

#include "isotope/source.h"

namespace isotope::bench {

struct SuiteOptions {
  bool quick = false;
  std::string json;
  int threads = 0;
  std::string data;  // the shared volumes' folder
  std::vector<std::string> datasets;
  std::string work_dir;
  int64_t cache_mb = OpenOptions{}.cache_mb;
  bool quiet = false;
  bool scale = false;
  int64_t scale_size = 2048;
  // Another isotope executable (another commit's, built as README.md's `isotope bench` says): convert and
  // the one-shot coarse surfaces of each dataset timed with it and with this one, in alternation.
  std::string reference;
};

// Runs the suite (or, with `scale`, the large-volume row) and prints its tables; writes `json`.
// Throws IoError (a missing volume, an interrupted run, a child that failed) and OptionError
// ("dataset") for a dataset name that is not in the suite. Returns the exit code.
int run_suite(const SuiteOptions& options);

}  // namespace isotope::bench
