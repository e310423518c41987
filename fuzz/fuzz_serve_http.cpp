// libFuzzer target: whatever a client sends on one connection to `isotope serve` (docs/SERVE.md),
// answered by the server itself: the request line, every header (Range, Expect, Connection,
// Content-Length among them), a body, several requests kept alive, through cpp-httplib's parser,
// the server's connection limits (docs/SERVE.md) and the server's routes, extractions included
// (from a small store made once). Whatever the bytes, the server must answer or close the
// connection within the fuzzer's timeout, without a crash, a sanitizer report or a large allocation.
#include <fcntl.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cerrno>
#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <thread>

#include "engine/synthetic/fields.h"
#include "fuzz/fuzz_temp_file.h"
#include "isotope/convert.h"
#include "tools/serve/viewer_server.h"

namespace {

isotope::tools::ViewerServer& server() {
  static isotope::tools::ViewerServer* s = [] {
    const std::string store = isotope::fuzz::temp_path(".isotope");
    isotope::ConvertOptions options;
    options.brick_bits = 3;
    isotope::convert(isotope::generate_sphere(9), store, options);
    isotope::tools::ViewerServer::Settings settings;
    settings.store = store;
    settings.cache_mb = 16;
    auto* made = new isotope::tools::ViewerServer(settings);  // opened: the file may go
    std::filesystem::remove(store);
    // Bound (never listening): a server that is not bound counts as stopping, and would close
    // every connection unread.
    made->bind("127.0.0.1", 0);
    return made;
  }();
  return *s;
}

// The client's side: sends INPUT, then half-closes, while reading (and dropping) whatever the
// server answers, until the server closes.
void client(int fd, const uint8_t* data, size_t size) {
  ::fcntl(fd, F_SETFL, ::fcntl(fd, F_GETFL) | O_NONBLOCK);
  bool writing = true;
  if (size == 0) ::shutdown(fd, SHUT_WR), writing = false;
  char sink[65536];
  for (;;) {
    pollfd p{fd, static_cast<short>(POLLIN | (writing ? POLLOUT : 0)), 0};
    if (::poll(&p, 1, 30000) <= 0) break;
    if (writing && (p.revents & POLLOUT)) {
      const ssize_t n = ::send(fd, data, size, MSG_NOSIGNAL);
      if (n > 0) data += n, size -= static_cast<size_t>(n);
      if ((n < 0 && errno != EAGAIN) || size == 0) ::shutdown(fd, SHUT_WR), writing = false;
    }
    if (p.revents & (POLLIN | POLLHUP | POLLERR)) {
      const ssize_t n = ::recv(fd, sink, sizeof sink, 0);
      if (n == 0 || (n < 0 && errno != EAGAIN)) break;
    }
  }
  ::close(fd);
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  isotope::tools::ViewerServer& s = server();
  int fds[2];
  if (::socketpair(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0, fds) != 0) std::abort();  // the harness, not a finding
  std::thread peer(client, fds[0], data, size);
  s.answer_connection(fds[1]);
  peer.join();
  return 0;
}
