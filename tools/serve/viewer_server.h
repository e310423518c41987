#pragma once
// `isotope serve`'s HTTP server (docs/SERVE.md): the embedded viewer, the store's summary, and
// extractions through the parallel paged engine, as binary meshes with their reports. Requests run
// concurrently on the server's threads; a page's newer request supersedes its older ones.
#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>

#include "isotope/source.h"
#include "tools/serve/http_limits.h"

namespace isotope::tools {

class ViewerServer {
 public:
  struct Settings {
    std::string store;                          // made by isotope convert
    int64_t cache_mb = OpenOptions{}.cache_mb;  // decoded bricks, shared by all requests
    bool log = false;                           // a line per extraction on stderr
    HttpLimits limits;                          // what one client may hold (docs/SERVE.md, "Limits")
    // The bodies of the responses being sent, at most (one alone may be larger): clients that
    // do not read what they asked for cannot make the server hold more.
    size_t response_budget_bytes = size_t{512} << 20;
  };
  // Opens the store and samples its histogram. Throws IoError (not a store, unreadable).
  explicit ViewerServer(const Settings& settings);
  ~ViewerServer();
  ViewerServer(const ViewerServer&) = delete;
  ViewerServer& operator=(const ViewerServer&) = delete;

  // Binds HOST:PORT (port 0: any free one) and returns the port. Throws IoError.
  int bind(const std::string& host, int port);
  // Answers requests until stop(); returns false if the server failed.
  bool listen();
  void stop();  // from any thread
  // Answers the requests that arrive on SOCKET (connected, e.g. one end of a socketpair) as the
  // server answers a connection it accepted, and closes it: for the fuzzer.
  void answer_connection(int socket);
  // Bytes of responses held for their clients now (ResponseBudget).
  size_t response_bytes_held() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// A loopback address (127.0.0.0/8, ::1, localhost): only this machine can connect.
bool is_loopback_host(const std::string& host);

}  // namespace isotope::tools
