#pragma once
// What the isotope command's subcommands share: extraction options and inputs read as the command
// line spells them (through the library's one parser and one opener), numbers in range, and
// progress on a terminal.
#include <chrono>
#include <cstdint>
#include <functional>
#include <string>
#include <utility>
#include <vector>

#include "isotope/source.h"
#include "tools/support/option_text.h"  // options and numbers as users type them

namespace CLI {
class Validator;
}

namespace isotope::tools {

// A CLI11 check of one extraction option (--NAME) by the reader every face shares (option_text):
// a value out of range is a usage error at parse time, in the same words as `isotope serve` uses.
CLI::Validator extract_option_check(std::string name);
// A CLI11 check of --threads by parse_thread_count: the words the Python module uses.
CLI::Validator thread_count_check();
// parse_extract_options() with an OptionError turned into a usage error (exit 2) naming --OPTION.
ExtractOptions parse_command_line_options(const std::vector<std::pair<std::string, std::string>>& given);

// Opens INPUT for extraction as every command does (isotope/source.h): --dims and --type as typed
// ("" = from the file name), --cache-mb for a store, the allocator kept for bricks, and with
// PROGRESS a line when the volume is read. --dims or --type that do not apply (a store) or do not
// parse are usage errors.
Source open_input(const std::string& path, const std::string& dims, const std::string& type, int64_t cache_mb,
                  bool progress);

// The run context of a command's extractions: with PROGRESS, the preprocessing bar for a volume's
// hierarchy that one of them builds first.
RunContext preprocessing_context(bool progress);

// Wall time since START.
inline double seconds_since(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

// Progress and timing lines go to stderr only when it is a terminal and --quiet is not given.
bool progress_enabled(bool quiet);

// The group of processes an MPI launcher started this one in (set by main, over MPI), or nullptr
// when it runs alone. Every rank runs the same command; only rank 0 speaks (progress, the summary,
// the error message) and writes the outputs.
const Distribution* process_group();
void set_process_group(const Distribution* group);
inline bool speaking_rank() { return !process_group() || process_group()->rank() == 0; }
// Runs work under settle_together (isotope/distribution.h) in a group, else just runs it.
void on_every_rank(const std::function<void()>& work);

// A one-line bar on stderr ("isotope: preprocessing  42%"), redrawn in place, ended at 100%.
std::function<void(double)> progress_bar(std::string label);

}  // namespace isotope::tools
