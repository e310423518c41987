// `isotope serve` keeps what one request freed for the next: asked the same extraction again, it
// faults in a small fraction of the fresh pages its first answer took. The server is a child
// process, so that its page faults (/proc/PID/stat) are its own; the Release binary's, since the
// sanitizers bring allocators of their own.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <httplib.h>
#include <poll.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdint>
#include <cstdlib>
#include <fstream>
#include <iterator>
#include <sstream>
#include <string>
#include <vector>

#include "tests/support/child_process.h"
#include "tests/support/temp_dir_test.h"

extern char** environ;

namespace isotope {
namespace {

// `isotope serve ARGS` running: its port, read from the line it prints first, and its minor page
// faults so far. Stopped with SIGINT (as Ctrl-C) when destroyed, killed if it does not stop.
class ServeChild {
 public:
  explicit ServeChild(const std::vector<std::string>& args) {
    std::vector<std::string> words = {ISOTOPE_BINARY, "serve"};
    words.insert(words.end(), args.begin(), args.end());
    std::vector<char*> argv;
    for (std::string& w : words) argv.push_back(w.data());
    argv.push_back(nullptr);
    int out[2];
    if (pipe2(out, O_CLOEXEC) != 0) return;
    posix_spawn_file_actions_t actions;
    posix_spawn_file_actions_init(&actions);
    posix_spawn_file_actions_adddup2(&actions, out[1], STDOUT_FILENO);  // dup2 clears close-on-exec
    if (posix_spawn(&pid_, argv[0], &actions, nullptr, argv.data(), environ) != 0) pid_ = -1;
    posix_spawn_file_actions_destroy(&actions);
    close(out[1]);
    out_ = out[0];     // kept open: the server's later output must not meet a closed pipe
    std::string line;  // "isotope: serving STORE on http://127.0.0.1:PORT/"
    pollfd ready{out_, POLLIN, 0};
    char c = 0;
    while (pid_ > 0 && poll(&ready, 1, 60000) == 1 && read(out_, &c, 1) == 1 && c != '\n') line += c;
    const size_t colon = line.rfind(':');
    if (colon != std::string::npos) port_ = std::atoi(line.c_str() + colon + 1);
  }
  ~ServeChild() {
    if (pid_ > 0) {
      kill(pid_, SIGINT);
      int status = 0;
      for (int waited = 0; waitpid(pid_, &status, WNOHANG) == 0; ++waited) {
        if (waited == 100) kill(pid_, SIGKILL);  // 10 s
        usleep(100000);
      }
    }
    if (out_ >= 0) close(out_);
  }
  ServeChild(const ServeChild&) = delete;
  ServeChild& operator=(const ServeChild&) = delete;

  int port() const { return port_; }
  // Field 10 of /proc/PID/stat: minor faults (pages mapped without reading from a disk: fresh
  // pages, among others), -1 once the process is gone.
  int64_t minor_faults() const {
    std::ifstream in("/proc/" + std::to_string(pid_) + "/stat");
    const std::string stat((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    const size_t comm_end = stat.rfind(')');
    if (comm_end == std::string::npos) return -1;
    std::istringstream fields(stat.substr(comm_end + 1));  // after "(comm)"
    std::string field;
    for (int i = 3; i <= 10; ++i) fields >> field;
    return fields ? std::stoll(field) : -1;
  }

 private:
  pid_t pid_ = -1;
  int out_ = -1;
  int port_ = 0;
};

// One malloc arena for the whole server process (docs/SERVE.md, "Memory from one request to the
// next"). In the arenas glibc gives threads of their own, a heap all of whose memory is free goes
// back to the kernel, and every request faulted its mesh, normals and topology arrays in again:
// embryo at eps 4, 25-30 k faults each time, as many as the first request; with one arena, under
// 500 from the fourth on.
class ServeMemory : public testing::TempDirTest {};

TEST_F(ServeMemory, ARepeatedRequestReusesTheMemoryTheLastOneFreed) {
  const std::string store = path("embryo.isotope");
  const testing::Child convert = testing::run_isotope(
      {"convert", std::string(ISOTOPE_TEST_DATA) + "/embryo_256x256x256_uint8.raw", store, "-q"}, path("log.txt"));
  ASSERT_EQ(convert.code, 0) << testing::slurp(path("log.txt"));
  ServeChild server({store, "--port", "0", "--quiet", "--cache-mb", "64"});
  ASSERT_GT(server.port(), 0) << "isotope serve did not say its port";
  httplib::Client client("127.0.0.1", server.port());
  client.set_read_timeout(120, 0);
  // One connection: the server frees a response before it reads the next request on it, so no
  // request starts while the last one's mesh is still held.
  client.set_keep_alive(true);
  std::vector<int64_t> faults;
  for (int request = 0; request < 6; ++request) {
    const int64_t before = server.minor_faults();
    ASSERT_GE(before, 0) << "isotope serve is gone";
    const httplib::Result r = client.Get("/api/extract?iso=64.5&eps=4");
    ASSERT_TRUE(r) << "request " << request << ": no answer";
    ASSERT_EQ(r->status, 200) << r->body;
    faults.push_back(server.minor_faults() - before);
    testing::report("serve_request_" + std::to_string(request) + "_minor_faults", static_cast<double>(faults.back()));
  }
  EXPECT_LT(faults[3] + faults[4] + faults[5], faults[0] / 2)
      << "the fourth to sixth requests faulted " << faults[3] << ", " << faults[4] << " and " << faults[5]
      << " pages in, the first " << faults[0];
}

}  // namespace
}  // namespace isotope
