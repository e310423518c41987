// Child processes and the page cache (run_child, evict_from_page_cache).
#include "tools/support/child_run.h"

#include <fcntl.h>
#include <spawn.h>
#include <sys/resource.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <climits>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <mutex>

extern char** environ;

namespace isotope::tools {

namespace {

// Spawns ARGS with its output into LOG and waits for it: everything run_child reports but the output.
ChildRun spawn_and_wait(const std::vector<std::string>& args, const std::string& log) {
  ChildRun r;
  std::vector<std::string> text = args;
  std::vector<char*> argv;
  for (std::string& a : text) argv.push_back(a.data());
  argv.push_back(nullptr);
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  // Not O_CLOEXEC: this descriptor is the child's stdout across its exec.
  posix_spawn_file_actions_addopen(&actions, 1, log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  posix_spawn_file_actions_adddup2(&actions, 1, 2);
  const auto start = std::chrono::steady_clock::now();
  pid_t pid = -1;
  const int spawned = !text.empty() && text[0].find('/') == std::string::npos
                          ? posix_spawnp(&pid, argv[0], &actions, nullptr, argv.data(), environ)
                          : posix_spawn(&pid, argv[0], &actions, nullptr, argv.data(), environ);
  posix_spawn_file_actions_destroy(&actions);
  if (spawned != 0) return r;
  int status = 0;
  rusage usage{};
  for (;;) {  // a signal (Ctrl-C, which the bench handles) interrupts the wait, not the child
    const pid_t done = wait4(pid, &status, 0, &usage);
    if (done == pid) break;
    if (done < 0 && errno != EINTR) return r;
  }
  r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  r.code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  r.max_rss_kb = usage.ru_maxrss;
  return r;
}

bool send_all(int fd, const void* data, size_t size) {
  const auto* p = static_cast<const char*>(data);
  while (size > 0) {
    const ssize_t n = ::send(fd, p, size, MSG_NOSIGNAL);  // a spawner gone is an error, not SIGPIPE
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) return false;
    p += n;
    size -= static_cast<size_t>(n);
  }
  return true;
}
bool receive_all(int fd, void* data, size_t size) {
  auto* p = static_cast<char*>(data);
  while (size > 0) {
    const ssize_t n = ::recv(fd, p, size, 0);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) return false;
    p += n;
    size -= static_cast<size_t>(n);
  }
  return true;
}

// A request: the strings' count, then each one's length and bytes (the arguments, then the log).
bool send_strings(int fd, const std::vector<std::string>& strings) {
  const auto count = static_cast<uint32_t>(strings.size());
  if (!send_all(fd, &count, sizeof count)) return false;
  for (const std::string& s : strings) {
    const auto size = static_cast<uint32_t>(s.size());
    if (!send_all(fd, &size, sizeof size) || !send_all(fd, s.data(), s.size())) return false;
  }
  return true;
}
bool receive_strings(int fd, std::vector<std::string>& strings) {
  uint32_t count = 0;
  if (!receive_all(fd, &count, sizeof count)) return false;
  strings.assign(count, {});
  for (std::string& s : strings) {
    uint32_t size = 0;
    if (!receive_all(fd, &size, sizeof size)) return false;
    s.resize(size);
    if (!receive_all(fd, s.data(), size)) return false;
  }
  return true;
}
struct Reply {
  int32_t code;
  double seconds;
  int64_t max_rss_kb;
};

// The spawner's socket in this process (-1: none), its pid, and one request at a time on it.
class Spawner {
 public:
  static Spawner& get() {
    static Spawner s;
    return s;
  }
  ~Spawner() {
    if (!started_) return;
    if (fd_ >= 0) ::close(fd_);  // the spawner reads the end, and exits
    int status = 0;
    ::waitpid(pid_, &status, 0);
  }
  void start() {
    const std::lock_guard<std::mutex> lock(mutex_);
    if (started_ || threads() != 1) return;
    int fds[2];
    if (::socketpair(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0, fds) != 0) return;
    const pid_t pid = ::fork();
    if (pid < 0) {
      ::close(fds[0]);
      ::close(fds[1]);
      return;
    }
    if (pid == 0) {
      ::close(fds[0]);
      serve(fds[1]);
    }
    ::close(fds[1]);
    fd_ = fds[0];
    pid_ = pid;
    started_ = true;
  }
  // False where there is no spawner: the caller spawns the child itself. A spawner gone (Ctrl-C
  // ends it with the child) is a child that did not run, not one to run again.
  bool run(const std::vector<std::string>& args, const std::string& log, ChildRun& r) {
    const std::lock_guard<std::mutex> lock(mutex_);
    if (!started_) return false;
    std::vector<std::string> request = args;
    request.push_back(log);
    Reply reply{-1, 0, 0};
    if (fd_ < 0 || !send_strings(fd_, request) || !receive_all(fd_, &reply, sizeof reply)) {
      if (fd_ >= 0) ::close(fd_);
      fd_ = -1;
      reply = {-1, 0, 0};
    }
    r.code = reply.code;
    r.seconds = reply.seconds;
    r.max_rss_kb = reply.max_rss_kb;
    return true;
  }

 private:
  // The spawner's loop: a child for each request, until the other end closes.
  [[noreturn]] static void serve(int fd) {
    std::vector<std::string> request;
    while (receive_strings(fd, request) && !request.empty()) {
      const std::string log = request.back();
      request.pop_back();
      const ChildRun r = spawn_and_wait(request, log);
      const Reply reply{r.code, r.seconds, r.max_rss_kb};
      if (!send_all(fd, &reply, sizeof reply)) break;
    }
    ::_exit(0);
  }
  static int threads() {
    std::error_code ec;
    int n = 0;
    for (auto it = std::filesystem::directory_iterator("/proc/self/task", ec); !ec && it != decltype(it)(); ++it) ++n;
    return ec ? 0 : n;
  }

  std::mutex mutex_;
  bool started_ = false;
  int fd_ = -1;
  pid_t pid_ = -1;
};

}  // namespace

void spawn_children_from_here() { Spawner::get().start(); }

ChildRun run_child(const std::vector<std::string>& args, const std::string& log) {
  ChildRun r;
  if (!Spawner::get().run(args, log, r)) r = spawn_and_wait(args, log);
  if (r.code == -1 && r.seconds == 0) return r;  // it did not start
  std::ifstream in(log, std::ios::binary);
  r.output.assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
  return r;
}

std::string self_executable() {
  char path[PATH_MAX];
  const ssize_t n = ::readlink("/proc/self/exe", path, sizeof path - 1);
  if (n <= 0) return "isotope";
  return std::string(path, static_cast<size_t>(n));
}

bool evict_from_page_cache(const std::string& file) {
  const int fd = ::open(file.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) return false;
  // Dirty pages are not dropped: a store just written must reach the disk first.
  const bool ok = ::fdatasync(fd) == 0 && ::posix_fadvise(fd, 0, 0, POSIX_FADV_DONTNEED) == 0;
  ::close(fd);
  return ok;
}

}  // namespace isotope::tools
