#pragma once
// The subcommands of the isotope tool. Each one registers its options on the application and
// returns the function that runs it after a successful parse; main() maps what it throws to
// exit codes (CLI::ParseError: usage, 2; anything else: runtime failure, 1). What they share is
// the command-line support (parse_command_line_options, open_input).
#include <functional>

#include "tools/support/command_line.h"

namespace CLI {
class App;
}

namespace isotope::tools {

using Command = std::function<int()>;  // returns the exit code

Command add_extract_command(CLI::App& app);   // isotope extract INPUT --iso V -o MESH.ply
Command add_generate_command(CLI::App& app);  // isotope generate SHAPE --size N -o FILE
Command add_demo_command(CLI::App& app);      // isotope demo [--out DIR] [--data DIR]
Command add_convert_command(CLI::App& app);   // isotope convert INPUT OUTPUT.isotope
Command add_info_command(CLI::App& app);      // isotope info STORE
Command add_verify_command(CLI::App& app);    // isotope verify STORE
Command add_sweep_command(CLI::App& app);     // isotope sweep INPUT --iso V --eps LIST --delta LIST
Command add_bench_command(CLI::App& app);     // isotope bench [--quick] [--json F]
Command add_serve_command(CLI::App& app);     // isotope serve STORE [--port P] [--host H]

}  // namespace isotope::tools
