#pragma once
// The server module's entry point (a command module, opened at run time): cpp-httplib, and OpenSSL with
// it, are loaded only by `isotope serve`.
#include <cstdint>
#include <string>

#include "isotope/source.h"

namespace isotope::tools {

struct ServeArgs {
  std::string store;
  std::string host = "127.0.0.1";
  int port = 8080;
  int64_t cache_mb = OpenOptions{}.cache_mb;
  int threads = 0;
  bool quiet = false;
};

inline constexpr const char* kServeModule = "isotope-serve";
inline constexpr const char* kServe = "isotope_serve";
// Serves until Ctrl-C; returns the exit code, throws what the command reports.
extern "C" int isotope_serve(const ServeArgs& args);
using Serve = decltype(isotope_serve);

}  // namespace isotope::tools
