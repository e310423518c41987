// isotope serve: a store in the browser (docs/SERVE.md). The server runs until Ctrl-C; a watcher
// thread turns the interrupt flag into a stop, so the listening socket is closed cleanly.
#include <malloc.h>
#include <oneapi/tbb/global_control.h>

#include <CLI/CLI.hpp>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <iostream>
#include <memory>
#include <optional>
#include <string>
#include <thread>

#include "isotope/error.h"
#include "tools/commands.h"
#include "tools/serve/viewer_server.h"
#include "tools/support/interrupt_guard.h"

namespace isotope::tools {
namespace {

struct ServeArgs {
  std::string store;
  std::string host = "127.0.0.1";
  int port = 8080;
  int64_t cache_mb = 512;
  int threads = 0;
  bool quiet = false;
};

int run_serve(const ServeArgs& a) {
  // One malloc arena for the whole process, set while this is its only thread (glibc fixes the
  // arenas a thread uses when it first allocates): a thread arena gives its heap back to the kernel
  // as soon as all of it is free, so every request's mesh, normals and topology arrays were fresh
  // pages; in the one arena the next request reuses them (docs/SERVE.md, "Memory from one request
  // to the next").
  mallopt(M_ARENA_MAX, 1);
  std::optional<tbb::global_control> threads;
  if (a.threads > 0) threads.emplace(tbb::global_control::max_allowed_parallelism, static_cast<size_t>(a.threads));
  const InterruptGuard interrupt;
  ViewerServer::Settings settings;
  settings.store = a.store;
  settings.cache_mb = a.cache_mb;
  settings.log = !a.quiet;
  ViewerServer server(settings);
  const int port = server.bind(a.host, a.port);
  if (!is_loopback_host(a.host))
    std::fprintf(stderr,
                 "isotope: warning: listening on %s, not loopback: anyone who reaches port %d can see this store\n",
                 a.host.c_str(), port);
  const std::string shown_host = a.host.find(':') != std::string::npos ? "[" + a.host + "]" : a.host;
  std::cout << "isotope: serving " << a.store << " on http://" << shown_host << ":" << port << "/" << std::endl;

  std::atomic<bool> done{false};
  std::thread watcher([&] {
    while (!done.load() && !InterruptGuard::interrupted()) std::this_thread::sleep_for(std::chrono::milliseconds(50));
    server.stop();
  });
  const bool ok = server.listen();
  done.store(true);
  watcher.join();
  if (InterruptGuard::interrupted()) {
    if (!a.quiet) std::fprintf(stderr, "isotope: stopped\n");
    return 0;
  }
  if (!ok) throw IoError("the server stopped on an error");
  return 0;
}

}  // namespace

Command add_serve_command(CLI::App& app) {
  auto a = std::make_shared<ServeArgs>();
  CLI::App* cmd = app.add_subcommand(
      "serve", "Explore a store in a web browser: live isovalue, error and topology controls (Ctrl-C stops)");
  cmd->add_option("STORE", a->store, "Store made by 'isotope convert'")->required();
  cmd->add_option("--port", a->port, "TCP port (0: any free port; the first line printed names it)")
      ->check(CLI::Range(0, 65535))
      ->capture_default_str();
  cmd->add_option("--host", a->host,
                  "Address to listen on; the default lets only this machine connect (0.0.0.0: every network)")
      ->capture_default_str();
  cmd->add_option("--cache-mb", a->cache_mb, "Memory for decoded bricks, in MB, shared by all requests")
      ->check(CLI::Range(int64_t{1}, int64_t{1} << 30))
      ->capture_default_str();
  cmd->add_option("--threads", a->threads, "Worker threads per extraction (0 = all cores)")
      ->check(thread_count_check())
      ->capture_default_str();
  cmd->add_flag("-q,--quiet", a->quiet, "Print only the line that names the address");
  return [a] { return run_serve(*a); };
}

}  // namespace isotope::tools
