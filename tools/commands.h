#pragma once
// The subcommands of the isotope tool. Each one registers its options on the application and
// returns the function that runs it after a successful parse; main() maps what it throws to
// exit codes (CLI::ParseError: usage, 2; anything else: runtime failure, 1).
#include <chrono>
#include <functional>
#include <optional>
#include <string>

namespace CLI {
class App;
}

namespace isotope::tools {

using Command = std::function<int()>;  // returns the exit code

// The largest --threads any command accepts: a usage error beyond, with the range in its message.
inline constexpr int kMaxThreads = 4096;

Command add_extract_command(CLI::App& app);   // isotope extract INPUT --iso V -o MESH.ply
Command add_generate_command(CLI::App& app);  // isotope generate SHAPE --size N -o FILE
Command add_demo_command(CLI::App& app);      // isotope demo [--out DIR] [--data DIR]
Command add_convert_command(CLI::App& app);   // isotope convert INPUT OUTPUT.isotope
Command add_info_command(CLI::App& app);      // isotope info STORE
Command add_verify_command(CLI::App& app);    // isotope verify STORE
Command add_sweep_command(CLI::App& app);     // isotope sweep INPUT --iso V --eps LIST --delta LIST
Command add_bench_command(CLI::App& app);     // isotope bench [--quick] [--json F]
Command add_serve_command(CLI::App& app);     // isotope serve STORE [--port P] [--host H]

// A real number as typed by a user: "0.25", "-3e-2" or a fraction "1/64"; nullopt otherwise.
std::optional<double> parse_real(const std::string& text);

// Wall time since START.
inline double seconds_since(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

// Progress and timing lines go to stderr only when it is a terminal and --quiet is not given.
bool progress_enabled(bool quiet);

// A one-line bar on stderr ("isotope: preprocessing  42%"), redrawn in place, ended at 100%.
std::function<void(double)> progress_bar(std::string label);

}  // namespace isotope::tools
