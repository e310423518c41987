// What the subcommands share: extraction options read as the command line spells them, and
// progress on a terminal.
#include "tools/support/command_line.h"

#include <unistd.h>

#include <CLI/CLI.hpp>
#include <cstdio>

#include "io/volume/raw_reader.h"  // parse_dims

namespace isotope::tools {

CLI::Validator extract_option_check(std::string name) {
  return CLI::Validator(
      [name](std::string& text) -> std::string {
        ExtractOptions scratch;
        try {
          set_extract_option(scratch, name, text);
        } catch (const OptionError& e) {
          return e.message;
        }
        return {};
      },
      "");
}

CLI::Validator thread_count_check() {
  return CLI::Validator(
      [](std::string& text) -> std::string {
        try {
          parse_thread_count(text);
        } catch (const OptionError& e) {
          return e.message;
        }
        return {};
      },
      "");
}

ExtractOptions parse_command_line_options(const std::vector<std::pair<std::string, std::string>>& given) {
  try {
    return parse_extract_options(given);
  } catch (const OptionError& e) {
    throw CLI::ValidationError("--" + e.option, e.message);
  }
}

Source open_input(const std::string& path, const std::string& dims, const std::string& type, int64_t cache_mb,
                  bool progress) {
  VolumeSpec spec;
  spec.path = path;
  if (!dims.empty()) {
    spec.dims = parse_dims(dims);
    if (!spec.dims) throw CLI::ValidationError("--dims", "must look like 64x64x32, got '" + dims + "'");
  }
  if (!type.empty()) {
    spec.type = parse_scalar_type(type);
    if (!spec.type)
      throw CLI::ValidationError("--type", "must be uint8, uint16, int16, float32 or float64, got '" + type + "'");
  }
  OpenOptions options;
  options.cache_mb = cache_mb;
  options.tune_allocator = true;
  try {
    Source source = open_volume(spec, options);
    const SourceInfo info = source.info();
    if (progress && info.values_in_memory)  // read at open (a volume file is read when extracted)
      std::fprintf(stderr, "isotope: read %lldx%lldx%lld volume in %.3f s\n", static_cast<long long>(info.dims[0]),
                   static_cast<long long>(info.dims[1]), static_cast<long long>(info.dims[2]), info.read_seconds);
    return source;
  } catch (const OptionError& e) {
    throw CLI::ValidationError("--" + e.option, e.message);
  }
}

RunContext preprocessing_context(bool progress) {
  RunContext run;
  if (progress) run.progress = progress_bar("preprocessing");
  return run;
}

bool progress_enabled(bool quiet) { return !quiet && speaking_rank() && isatty(STDERR_FILENO) == 1; }

namespace {
const Distribution* g_group = nullptr;
}
const Distribution* process_group() { return g_group; }
void set_process_group(const Distribution* group) { g_group = group; }
void on_every_rank(const std::function<void()>& work) { settle_together(g_group, work); }

std::function<void(double)> progress_bar(std::string label) {
  return [label = std::move(label)](double fraction) {
    std::fprintf(stderr, "\risotope: %s %3d%%%s", label.c_str(), static_cast<int>(100 * fraction + 0.5),
                 fraction >= 1.0 ? "\n" : "");
    std::fflush(stderr);
  };
}

}  // namespace isotope::tools
