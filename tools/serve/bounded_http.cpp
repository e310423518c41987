#include "tools/serve/bounded_http.h"

#include <arpa/inet.h>
#include <malloc.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <functional>
#include <optional>
#include <utility>
#include <vector>

#include "engine/core/huge_blocks.h"
#include "engine/extract/slab_march.h"

namespace isotope::tools {
namespace {

using Clock = std::chrono::steady_clock;

constexpr size_t kPiece = size_t{1} << 20;  // a response body is handed to the socket this much at a time

// When the connection a worker is serving was accepted: the pool's job sets it before the server
// serves the connection on the same thread (AcceptOrderPool).
thread_local Clock::time_point t_accepted;

// cpp-httplib's thread pool, with each connection's accept time handed to the worker that serves it.
class AcceptOrderPool final : public httplib::TaskQueue {
 public:
  explicit AcceptOrderPool(size_t workers) : pool_(workers) {}
  void enqueue(std::function<void()> fn) override {
    pool_.enqueue([fn = std::move(fn), accepted = Clock::now()] {
      t_accepted = accepted;
      fn();
    });
  }
  void shutdown() override { pool_.shutdown(); }

 private:
  httplib::ThreadPool pool_;
};

// A connection's socket as cpp-httplib's Stream, with the deadlines of HttpLimits. Reads are
// buffered (the request line and headers are read a byte at a time by the library).
class BoundedStream final : public httplib::Stream {
 public:
  BoundedStream(socket_t sock, const HttpLimits& limits, const std::atomic<socket_t>& server_socket,
                Clock::time_point accepted)
      : sock_(sock), limits_(limits), server_socket_(server_socket), accepted_(accepted) {}

  // Waits up to the idle timeout for a request's first byte; false when none came or the server
  // stops. The first request's deadline counts from the accept, a later one's from now; the next
  // response's pace anew.
  bool next_request() {
    const bool first = !served_;
    served_ = true;
    const Clock::time_point from = first ? accepted_ : Clock::now();
    if (expired_ || (buffered_ == 0 && !wait(POLLIN, from + limits_.idle_timeout))) return false;
    read_deadline_ = (first ? accepted_ : Clock::now()) + limits_.request_deadline;
    send_start_.reset();
    sent_ = 0;
    return true;
  }

  bool is_readable() const override { return buffered_ > 0 || wait(POLLIN, read_deadline_); }
  bool is_writable() const override { return wait(POLLOUT, send_deadline()); }

  ssize_t read(char* ptr, size_t size) override {
    if (buffered_ == 0) {
      if (!wait(POLLIN, read_deadline_)) {
        // The request is not whole by its deadline: the library answers 400 and would read on;
        // the connection ends here instead.
        expired_ = true;
        return -1;
      }
      ssize_t n;
      do n = ::recv(sock_, buffer_.data(), buffer_.size(), 0);
      while (n < 0 && errno == EINTR);
      if (n <= 0) return n;
      offset_ = 0;
      buffered_ = static_cast<size_t>(n);
    }
    const size_t n = std::min(size, buffered_);
    std::copy_n(buffer_.data() + offset_, n, ptr);
    offset_ += n;
    buffered_ -= n;
    return static_cast<ssize_t>(n);
  }

  // All of it, as a blocking send would (the library writes some lines with one call and does not
  // look at the count), or -1 when the response falls behind its pace or the peer is gone.
  ssize_t write(const char* ptr, size_t size) override {
    if (!send_start_) send_start_ = Clock::now();
    for (size_t done = 0; done < size;) {
      if (!wait(POLLOUT, send_deadline())) return -1;
      const ssize_t n = ::send(sock_, ptr + done, size - done, MSG_NOSIGNAL | MSG_DONTWAIT);
      if (n < 0 && errno != EINTR && errno != EAGAIN && errno != EWOULDBLOCK) return -1;
      if (n > 0) done += static_cast<size_t>(n), sent_ += static_cast<size_t>(n);
    }
    return static_cast<ssize_t>(size);
  }

  void get_remote_ip_and_port(std::string& ip, int& port) const override { address(::getpeername, ip, port); }
  void get_local_ip_and_port(std::string& ip, int& port) const override { address(::getsockname, ip, port); }
  socket_t socket() const override { return sock_; }

 private:
  // By when the response must have gone this far: the grace, then the pace (a response not begun
  // is under its grace).
  Clock::time_point send_deadline() const {
    const Clock::time_point start = send_start_.value_or(Clock::now());
    const double seconds = static_cast<double>(sent_) / limits_.min_send_bytes_per_second;
    return start + limits_.send_grace +
           std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(seconds));
  }

  // Waits for EVENTS on the socket until DEADLINE, in slices, so that a stopping server is seen
  // at once; false when the deadline passed with nothing ready, the server stops, or the peer is
  // gone. What is ready already is taken whatever the time.
  bool wait(short events, Clock::time_point deadline) const {
    for (;;) {
      if (server_socket_ == INVALID_SOCKET) return false;
      const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - Clock::now()).count();
      pollfd p{sock_, events, 0};
      const int r = ::poll(&p, 1, static_cast<int>(std::clamp<long long>(left, 0, 100)));
      if (r < 0 && errno != EINTR) return false;
      if (r > 0) return (p.revents & events) != 0 || (p.revents & POLLHUP && events == POLLIN);
      if (left <= 0) return false;
    }
  }

  template <typename Name>
  void address(Name name, std::string& ip, int& port) const {
    sockaddr_storage a{};
    socklen_t length = sizeof a;
    ip.clear();
    port = 0;
    if (name(sock_, reinterpret_cast<sockaddr*>(&a), &length) != 0) return;
    char text[INET6_ADDRSTRLEN] = "";
    if (a.ss_family == AF_INET) {
      const auto* v4 = reinterpret_cast<const sockaddr_in*>(&a);
      ::inet_ntop(AF_INET, &v4->sin_addr, text, sizeof text);
      port = ntohs(v4->sin_port);
    } else if (a.ss_family == AF_INET6) {
      const auto* v6 = reinterpret_cast<const sockaddr_in6*>(&a);
      ::inet_ntop(AF_INET6, &v6->sin6_addr, text, sizeof text);
      port = ntohs(v6->sin6_port);
    }
    ip = text;
  }

  socket_t sock_;
  HttpLimits limits_;
  const std::atomic<socket_t>& server_socket_;
  Clock::time_point accepted_, read_deadline_;
  bool served_ = false;
  std::optional<Clock::time_point> send_start_;
  size_t sent_ = 0;
  std::vector<char> buffer_ = std::vector<char>(4096);
  size_t offset_ = 0, buffered_ = 0;
  bool expired_ = false;
};

}  // namespace

BoundedHttpServer::BoundedHttpServer(const HttpLimits& limits) : limits_(limits) {
  new_task_queue = [workers = limits.workers] { return new AcceptOrderPool(workers); };
}

bool BoundedHttpServer::process_and_close_socket(socket_t sock) {
  bool ok = false;
  {
    // Served outside the pool (a test, the fuzzer): accepted now.
    const Clock::time_point accepted = t_accepted == Clock::time_point{} ? Clock::now() : t_accepted;
    t_accepted = {};
    BoundedStream stream(sock, limits_, svr_sock_, accepted);
    for (size_t left = keep_alive_max_count_; left > 0 && stream.next_request(); --left) {
      bool closed = false;
      ok = process_request(stream, left == 1, closed, [](httplib::Request& req) {
        req.ranges.clear();           // the whole body, once (200, not 206)
        req.headers.erase("Expect");  // no interim 100 Continue to start the response's pace early
      });
      if (!ok || closed) break;
    }
  }
  ::shutdown(sock, SHUT_RDWR);
  ::close(sock);
  return ok;
}

std::shared_ptr<void> ResponseBudget::hold(size_t bytes) {
  {
    const std::lock_guard<std::mutex> lock(mutex_);
    if (held_ > 0 && held_ + bytes > budget_) return nullptr;
    held_ += bytes;
  }
  // Not null (a null shared_ptr would read as a refusal); the deleter only gives the bytes back.
  return std::shared_ptr<void>(static_cast<void*>(this), [this, bytes](void*) { release(bytes); });
}

void ResponseBudget::release(size_t bytes) {
  const std::lock_guard<std::mutex> lock(mutex_);
  held_ -= bytes;
}

namespace {
constexpr size_t kKeptBusy = size_t{256} << 20, kKeptIdle = size_t{64} << 20;

// The huge-block store keeps freed blocks while some returner runs (servers, one each).
std::mutex returners_mutex;
int returners = 0;
}  // namespace

MemoryReturner::MemoryReturner() {
  {
    const std::lock_guard<std::mutex> lock(returners_mutex);
    if (returners++ == 0) detail::keep_freed_huge_blocks(kKeptBusy);
  }
  thread_ = std::thread([this] { run(); });
}

MemoryReturner::~MemoryReturner() {
  {
    const std::lock_guard<std::mutex> lock(mutex_);
    stop_ = true;
  }
  wake_.notify_one();
  thread_.join();
  const std::lock_guard<std::mutex> lock(returners_mutex);
  if (--returners == 0) detail::keep_freed_huge_blocks(0);
}

void MemoryReturner::busy() {
  last_busy_ns_ = std::chrono::duration_cast<std::chrono::nanoseconds>(Clock::now().time_since_epoch()).count();
}

void MemoryReturner::run() {
  // Idle: ten seconds without an extraction. A viewer's user pauses between requests for seconds;
  // within them the next request finds the memory the last one freed (docs/SERVE.md).
  constexpr auto kIdleAfter = std::chrono::seconds(10);
  // malloc_trim walks the whole heap and advises every free page in it, those it gave back before
  // included, which still count as free (mallinfo2's fordblks): so not whenever fordblks is above
  // what may be kept, but when what was freed since the last trim is. `given_back` follows fordblks
  // down from the last trim (allocations take the given-back pages first), so fordblks - given_back
  // is what has been freed and kept since.
  size_t given_back = 0;
  std::unique_lock<std::mutex> lock(mutex_);
  while (!wake_.wait_for(lock, std::chrono::milliseconds(250), [this] { return stop_; })) {
    const auto since_busy = Clock::now().time_since_epoch() - std::chrono::nanoseconds(last_busy_ns_.load());
    const size_t kept = since_busy > kIdleAfter ? kKeptIdle : kKeptBusy;
    if (since_busy > kIdleAfter) give_back_slab_memory();  // to malloc and the huge-block store, given back below
    detail::give_back_huge_blocks(kept);
    const size_t free_bytes = mallinfo2().fordblks;
    given_back = std::min(given_back, free_bytes);
    if (free_bytes - given_back > kept) {
      malloc_trim(0);
      given_back = mallinfo2().fordblks;
    }
  }
}

bool ResponseBudget::exhausted() const {
  const std::lock_guard<std::mutex> lock(mutex_);
  return held_ >= budget_;
}

size_t ResponseBudget::held() const {
  const std::lock_guard<std::mutex> lock(mutex_);
  return held_;
}

void set_held_content(httplib::Response& res, const char* body, size_t size, const char* content_type,
                      std::shared_ptr<const void> hold) {
  set_held_content(res, {std::string_view(body, size)}, content_type, std::move(hold));
}

void set_held_content(httplib::Response& res, std::vector<std::string_view> parts, const char* content_type,
                      std::shared_ptr<const void> hold) {
  size_t size = 0;
  for (const std::string_view p : parts) size += p.size();
  res.set_content_provider(
      size, content_type,
      [parts = std::move(parts), hold = std::move(hold)](size_t offset, size_t length, httplib::DataSink& sink) {
        // The part that holds `offset`, and as much of it as the sink takes at once.
        size_t i = 0;
        for (; i < parts.size() && offset >= parts[i].size(); ++i) offset -= parts[i].size();
        if (i == parts.size()) return false;  // past the end: httplib asks no such thing
        return sink.write(parts[i].data() + offset, std::min({length, kPiece, parts[i].size() - offset}));
      });
}

}  // namespace isotope::tools
