#pragma once
// What one HTTP client can hold of `isotope serve` (docs/SERVE.md, "Limits"), on top of cpp-httplib:
// - a deadline for each whole request, head and body, from its first byte: a client that drips
//   its header lines one at a time loses the connection when the deadline passes, however often it
//   sends (cpp-httplib's read timeout restarts with every byte that arrives);
// - a pace for each response: after a grace period, a client must have taken the response at no
//   less than a minimum average rate, or the connection is closed and what it held freed;
// - Range headers ignored: the whole body is sent once (RFC 9110 allows a server to), so that no
//   request can multiply a body by the ranges it lists;
// - a budget for the bodies of responses in flight (ResponseBudget), which the handlers consult.
// Connections are served as cpp-httplib serves them otherwise (keep-alive, its limits on the
// request line and headers).
#include <httplib.h>

#include <chrono>
#include <cstddef>
#include <memory>
#include <mutex>

namespace isotope::tools {

struct HttpLimits {
  // Threads answering connections: each holds one while it reads a request (at most the deadline),
  // runs it and sends the response. More connections wait for a thread in accept order.
  size_t workers = 128;
  std::chrono::milliseconds request_deadline{5000};  // a request's head and body, from its first byte
  std::chrono::milliseconds idle_timeout{5000};      // between the requests of a kept-alive connection
  std::chrono::milliseconds send_grace{10000};       // a response's start, before the pace counts
  double min_send_bytes_per_second = 256 * 1024;     // the pace, on average, after the grace
};

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

// Gives the memory freed so far back to the system once more than 256 MB of it is kept. glibc keeps
// freed memory in its arenas (up to 8 per core, one per thread that allocated, each keeping up to
// the trim threshold, which isotope::open_volume raises for the brick cache): a server's worker
// threads would otherwise keep a crowd's meshes in its RSS long after their clients left.
void release_free_memory();

// BODY as RES's content, sent from where it lies (no copy) in pieces; HOLD (e.g. a ResponseBudget
// hold, or the owner of BODY) is kept until the response is destroyed.
void set_held_content(httplib::Response& res, const char* body, size_t size, const char* content_type,
                      std::shared_ptr<const void> hold);

}  // namespace isotope::tools
