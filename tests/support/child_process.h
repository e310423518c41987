#pragma once
// The isotope command as a child process whose peak memory is measured (wait4's ru_maxrss), and
// byte comparison of large files: what the memory tests (convert, extract) share.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <iterator>
#include <string>
#include <vector>

#include "tools/support/child_run.h"

namespace isotope::testing {

struct Child {
  int code = -1;
  int64_t max_rss_kb = 0;  // ru_maxrss, KB on Linux
  double seconds = 0;
};

// Runs the isotope binary with ARGS, stdout into OUT (stderr too), and waits for it alone
// (as run_child, which isotope bench measures its processes with).
inline Child run_isotope(const std::vector<std::string>& args, const std::string& out) {
  std::vector<std::string> argv = {ISOTOPE_BINARY};
  argv.insert(argv.end(), args.begin(), args.end());
  const tools::ChildRun r = tools::run_child(argv, out);
  if (r.code == -1) ADD_FAILURE() << "isotope did not start or did not exit normally: " << r.output;
  return {r.code, r.max_rss_kb, r.seconds};
}

inline std::string slurp(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

// Compared block by block: stores and eps-0 meshes are tens to hundreds of MB.
inline bool same_bytes(const std::string& a, const std::string& b) {
  namespace fs = std::filesystem;
  if (!fs::exists(a) || !fs::exists(b) || fs::file_size(a) != fs::file_size(b)) return false;
  std::ifstream fa(a, std::ios::binary), fb(b, std::ios::binary);
  std::vector<char> ba(1 << 20), bb(1 << 20);
  while (fa && fb) {
    fa.read(ba.data(), static_cast<std::streamsize>(ba.size()));
    fb.read(bb.data(), static_cast<std::streamsize>(bb.size()));
    if (fa.gcount() != fb.gcount() || !std::equal(ba.begin(), ba.begin() + fa.gcount(), bb.begin())) return false;
  }
  return true;
}

// A number worth quoting: into the test's XML properties and onto stdout.
inline void report(const std::string& key, double value) {
  ::testing::Test::RecordProperty(key, std::to_string(value));
  std::cout << "[ measured ] " << key << " = " << value << std::endl;
}

}  // namespace isotope::testing
