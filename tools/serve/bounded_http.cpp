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
#include <optional>
#include <vector>

namespace isotope::tools {
namespace {

using Clock = std::chrono::steady_clock;

constexpr size_t kPiece = size_t{1} << 20;  // a response body is handed to the socket this much at a time

// A connection's socket as cpp-httplib's Stream, with the deadlines of HttpLimits. Reads are
// buffered (the request line and headers are read a byte at a time by the library).
class BoundedStream final : public httplib::Stream {
 public:
  BoundedStream(socket_t sock, const HttpLimits& limits, const std::atomic<socket_t>& server_socket)
      : sock_(sock), limits_(limits), server_socket_(server_socket) {}

  // Waits up to the idle timeout for a request's first byte; false when none came or the server
  // stops. Then the request's deadline counts from now, and the next response's pace anew.
  bool next_request() {
    if (expired_ || (buffered_ == 0 && !wait(POLLIN, Clock::now() + limits_.idle_timeout))) return false;
    read_deadline_ = Clock::now() + limits_.request_deadline;
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
  // at once; false when the deadline passed, the server stops, or the peer is gone.
  bool wait(short events, Clock::time_point deadline) const {
    for (;;) {
      if (server_socket_ == INVALID_SOCKET) return false;
      const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - Clock::now()).count();
      if (left <= 0) return false;
      pollfd p{sock_, events, 0};
      const int r = ::poll(&p, 1, static_cast<int>(std::min<long long>(left, 100)));
      if (r < 0 && errno != EINTR) return false;
      if (r > 0) return (p.revents & events) != 0 || (p.revents & POLLHUP && events == POLLIN);
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
  Clock::time_point read_deadline_;
  std::optional<Clock::time_point> send_start_;
  size_t sent_ = 0;
  std::vector<char> buffer_ = std::vector<char>(4096);
  size_t offset_ = 0, buffered_ = 0;
  bool expired_ = false;
};

}  // namespace

BoundedHttpServer::BoundedHttpServer(const HttpLimits& limits) : limits_(limits) {
  new_task_queue = [workers = limits.workers] { return new httplib::ThreadPool(workers); };
}

bool BoundedHttpServer::process_and_close_socket(socket_t sock) {
  bool ok = false;
  {
    BoundedStream stream(sock, limits_, svr_sock_);
    for (size_t left = keep_alive_max_count_; left > 0 && stream.next_request(); --left) {
      bool closed = false;
      // The ranges parsed from a Range header, dropped: the whole body, once (200, not 206).
      ok = process_request(stream, left == 1, closed, [](httplib::Request& req) { req.ranges.clear(); });
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
  {
    const std::lock_guard<std::mutex> lock(mutex_);
    held_ -= bytes;
  }
  release_free_memory();
}

void release_free_memory() {
  // Kept up to a bound: an extraction reuses what the last one freed (trimming after each would
  // have it fault every page in again, 20 ms of a 120 ms extraction at 117 k triangles).
  constexpr size_t kKeptFreeBytes = size_t{256} << 20;
  if (mallinfo2().fordblks > kKeptFreeBytes) malloc_trim(0);
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
  res.set_content_provider(size, content_type,
                           [body, hold = std::move(hold)](size_t offset, size_t length, httplib::DataSink& sink) {
                             return sink.write(body + offset, std::min(length, kPiece));
                           });
}

}  // namespace isotope::tools
