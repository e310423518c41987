#pragma once
// What one HTTP client may hold of `isotope serve` (docs/SERVE.md, "Limits"), as numbers; the server
// that enforces them is BoundedHttpServer.
#include <chrono>
#include <cstddef>

namespace isotope::tools {

struct HttpLimits {
  // Threads answering connections: each holds one while it reads a request (at most the deadline),
  // runs it and sends the response. More connections wait for a thread in accept order.
  size_t workers = 128;
  // A connection's first request must be whole this long after the connection was accepted (time
  // spent waiting for a worker included), a later one this long after its first byte. A request
  // whose bytes are all there when a worker reads it is read whatever the time.
  std::chrono::milliseconds request_deadline{5000};
  std::chrono::milliseconds idle_timeout{5000};  // between the requests of a kept-alive connection
  std::chrono::milliseconds send_grace{10000};   // a response's start, before the pace counts
  double min_send_bytes_per_second = 64 * 1024;  // the pace, on average, after the grace
};

}  // namespace isotope::tools
