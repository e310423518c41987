#pragma once
// What one HTTP client can hold of `isotope serve` (docs/SERVE.md, "Limits"), on top of cpp-httplib:
// - a deadline for each whole request, head and body (HttpLimits): a client that drips its header
//   lines one at a time loses the connection when the deadline passes, however often it sends
//   (cpp-httplib's read timeout restarts with every byte that arrives); a connection's first
//   request counts from its accept, so that a crowd of such clients queued for a worker is cut as
//   soon as each is reached;
// - a pace for each response: after a grace period, a client must have taken the response at no
//   less than a minimum average rate, or the connection is closed and what it held freed;
// - Range headers ignored: the whole body is sent once (RFC 9110 allows a server to), so that no
//   request can multiply a body by the ranges it lists; Expect headers ignored too (no request
//   here has a body worth waiting for);
// - a budget for the bodies of responses in flight (ResponseBudget), which the handlers consult,
//   and freed memory given back to the system (MemoryReturner).
// Connections are served as cpp-httplib serves them otherwise (keep-alive, its limits on the
// request line and headers).
#include <httplib.h>

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstddef>
#include <memory>
#include <mutex>
#include <string_view>
#include <thread>
#include <vector>

#include "tools/serve/http_limits.h"

namespace isotope::tools {

class BoundedHttpServer : public httplib::Server {
 public:
  explicit BoundedHttpServer(const HttpLimits& limits);
  // Answers the requests of one connected socket as a worker does, then closes it: what the accept
  // loop hands each worker; public for the fuzzer, which feeds whole connections.
  bool serve_connection(socket_t sock) { return process_and_close_socket(sock); }

 private:
  bool process_and_close_socket(socket_t sock) override;
  HttpLimits limits_;
};

// Bytes held by the bodies of responses being sent, against a budget: a body that would take the
// total beyond it is refused (the handler answers 503), unless nothing else is held, so that one
// body larger than the whole budget is still served. A hold ends when its response is destroyed,
// sent or abandoned.
class ResponseBudget {
 public:
  explicit ResponseBudget(size_t budget_bytes) : budget_(budget_bytes) {}
  // A hold on BYTES, or nullptr when they do not fit.
  std::shared_ptr<void> hold(size_t bytes);
  bool exhausted() const;
  size_t held() const;
  size_t budget() const { return budget_; }

 private:
  void release(size_t bytes);
  mutable std::mutex mutex_;
  size_t budget_, held_ = 0;
};

// Gives freed memory back to the system from a thread of its own, every quarter second: once more
// than 256 MB of it is kept, or 64 MB after ten seconds without an extraction. glibc keeps freed
// memory in its arenas (up to the trim threshold, which isotope::open_volume raises for the brick
// cache), the huge-block store keeps freed large arrays (detail::keep_freed_huge_blocks, turned
// on by the returner) and reservations (counted with them), and an eps-0 extraction leaves its
// slabs' memory to the next (given back once idle): a server would otherwise keep a crowd's meshes in its RSS long
// after their clients left. Not after every request: the next extraction reuses what the last one freed, and giving it
// back would have it fault every page in again (20 ms of a 120 ms extraction of 117 k triangles).
class MemoryReturner {
 public:
  MemoryReturner();
  ~MemoryReturner();
  MemoryReturner(const MemoryReturner&) = delete;
  MemoryReturner& operator=(const MemoryReturner&) = delete;
  void busy();  // an extraction starts or ends now

 private:
  void run();
  std::atomic<int64_t> last_busy_ns_{0};
  std::mutex mutex_;
  std::condition_variable wake_;
  bool stop_ = false;
  std::thread thread_;
};

// BODY as RES's content, sent from where it lies (no copy) in pieces; HOLD (e.g. a ResponseBudget
// hold, or the owner of BODY) is kept until the response is destroyed.
void set_held_content(httplib::Response& res, const char* body, size_t size, const char* content_type,
                      std::shared_ptr<const void> hold);
// The same for a body that lies in several places: PARTS one after the other.
void set_held_content(httplib::Response& res, std::vector<std::string_view> parts, const char* content_type,
                      std::shared_ptr<const void> hold);

}  // namespace isotope::tools
