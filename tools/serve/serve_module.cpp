// The server module (isotope_serve, its entry point): `isotope serve` once its options are parsed. The
// server runs until Ctrl-C; a watcher thread turns the interrupt flag into a stop, so the
// listening socket is closed cleanly.
#include "tools/serve/serve_module.h"

#include <malloc.h>
#include <oneapi/tbb/global_control.h>

#include <atomic>
#include <chrono>
#include <cstdio>
#include <iostream>
#include <optional>
#include <string>
#include <thread>

#include "isotope/error.h"
#include "tools/serve/viewer_server.h"
#include "tools/support/interrupt_guard.h"

namespace isotope::tools {

extern "C" int isotope_serve(const ServeArgs& a) {
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

}  // namespace isotope::tools
