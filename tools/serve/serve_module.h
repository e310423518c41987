#pragma once
// The server module's entry point (tools/support/command_module.h): cpp-httplib, and OpenSSL with
// it, are loaded only by `isotope serve`.
#include <cstdint>
#include <string>

namespace isotope::tools {

struct ServeArgs {
  std::string store;
  std::string host = "127.0.0.1";
  int port = 8080;
  int64_t cache_mb = 512;
  int threads = 0;
  bool quiet = false;
};

inline constexpr const char* kServeModule = "isotope-serve";
inline constexpr const char* kServe = "isotope_serve";
// Serves until Ctrl-C; returns the exit code, throws what the command reports.
extern "C" int isotope_serve(const ServeArgs& args);
using Serve = decltype(isotope_serve);

}  // namespace isotope::tools
