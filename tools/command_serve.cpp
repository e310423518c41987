// isotope serve: a store in the browser (docs/SERVE.md). The options are read here; the server
// itself is a module of the command (the server module, isotope_serve), opened only by this command.
#include <CLI/CLI.hpp>
#include <memory>

#include "tools/commands.h"
#include "tools/serve/serve_module.h"
#include "tools/support/command_module.h"

namespace isotope::tools {

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
  return [a] { return module_function<Serve>(kServeModule, kServe)(*a); };
}

}  // namespace isotope::tools
