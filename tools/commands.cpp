// What the subcommands share: reading numbers as users type them, and progress on a terminal.
#include "tools/commands.h"

#include <unistd.h>

#include <charconv>
#include <cstdio>

namespace isotope::tools {

std::optional<double> parse_real(const std::string& text) {
  auto parse_one = [](std::string_view s) -> std::optional<double> {
    if (s.empty()) return std::nullopt;
    if (s.front() == '+') s.remove_prefix(1);
    double v = 0;
    const auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), v);
    if (ec != std::errc() || end != s.data() + s.size()) return std::nullopt;
    return v;
  };
  const size_t slash = text.find('/');
  if (slash == std::string::npos) return parse_one(text);
  const auto num = parse_one(std::string_view(text).substr(0, slash));
  const auto den = parse_one(std::string_view(text).substr(slash + 1));
  if (!num || !den || *den == 0) return std::nullopt;
  return *num / *den;
}

bool progress_enabled(bool quiet) { return !quiet && isatty(STDERR_FILENO) == 1; }

std::function<void(double)> progress_bar(std::string label) {
  return [label = std::move(label)](double fraction) {
    std::fprintf(stderr, "\risotope: %s %3d%%%s", label.c_str(), static_cast<int>(100 * fraction + 0.5),
                 fraction >= 1.0 ? "\n" : "");
    std::fflush(stderr);
  };
}

}  // namespace isotope::tools
