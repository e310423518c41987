#include "tools/support/option_text.h"

#include <charconv>
#include <climits>
#include <cmath>
#include <limits>

#include "isotope/error.h"
#include "isotope/run_context.h"

namespace isotope {
namespace {

// The value of an enumeration whose name (to_string) is TEXT, among VALUES; nullopt for none.
template <class Enum, size_t N>
std::optional<Enum> value_named(std::string_view text, const Enum (&values)[N]) {
  for (const Enum v : values)
    if (to_string(v) == text) return v;
  return std::nullopt;
}
constexpr TopologyMode kTopologyModes[] = {TopologyMode::none, TopologyMode::paper, TopologyMode::preserve,
                                           TopologyMode::simplify};
constexpr SimplificationWeight kWeights[] = {SimplificationWeight::interval, SimplificationWeight::gradient,
                                             SimplificationWeight::size};
constexpr ErrorIndicator kErrorIndicators[] = {ErrorIndicator::bound, ErrorIndicator::surplus};

constexpr size_t kMaxValueChars = kMaxOptionTextChars;

// A number's shortest exact form, which reads back as the same double.
std::string shortest(double value) {
  char buffer[64];
  const auto end = std::to_chars(buffer, buffer + sizeof buffer, value).ptr;
  return std::string(buffer, static_cast<size_t>(end - buffer));
}
// A value as the messages show it: the text typed, or a number's shortest exact form.
std::string quoted(std::string_view text) {
  return "'" + std::string(text.substr(0, kMaxValueChars)) + (text.size() > kMaxValueChars ? "...'" : "'");
}
std::string quoted(double value) { return quoted(shortest(value)); }

// Each option's check of a value, with the value as the message shows it.
double finite(std::string_view name, std::optional<double> v, const std::string& shown) {
  if (!v || !std::isfinite(*v)) throw OptionError(std::string(name), "must be a finite number, got " + shown);
  return *v;
}
double non_negative(std::string_view name, std::optional<double> v, const std::string& shown) {
  const double x = finite(name, v, shown);
  if (x < 0) throw OptionError(std::string(name), "must be >= 0, got " + shown);
  return x;
}
int64_t integer_in(std::string_view name, std::optional<int64_t> v, int64_t lo, int64_t hi, const char* meaning,
                   const std::string& shown) {
  if (!v || *v < lo || *v > hi)
    throw OptionError(std::string(name), "must be an integer in " + std::to_string(lo) + " .. " + std::to_string(hi) +
                                             " (" + meaning + "), got " + shown);
  return *v;
}
Focus& focus_of(ExtractOptions& o) {
  if (!o.focus) o.focus = Focus{};
  return *o.focus;
}

void set_real(ExtractOptions& o, std::string_view name, std::optional<double> v, const std::string& shown) {
  if (name == "iso") {
    o.iso = static_cast<float>(finite(name, v, shown));
    if (!std::isfinite(o.iso)) throw OptionError("iso", "is out of the float range: " + shown);
  } else if (name == "eps") {
    o.eps = non_negative(name, v, shown);
  } else if (name == "delta") {
    o.delta = non_negative(name, v, shown);
  } else {  // radius
    const double r = finite(name, v, shown);
    if (!(r > 0)) throw OptionError("radius", "must be > 0, got " + shown);
    focus_of(o).radius = r;
  }
}

// A whole number of at most 64 bits (nullopt otherwise).
std::optional<int64_t> integer(std::string_view text) {
  if (!text.empty() && text.front() == '+') text.remove_prefix(1);
  int64_t v = 0;
  const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), v);
  if (ec != std::errc() || end != text.data() + text.size()) return std::nullopt;
  return v;
}

void set_integer(ExtractOptions& o, std::string_view name, std::optional<int64_t> v, const std::string& shown) {
  if (name == "max-triangles")  // 0 would mean no budget, which is leaving the option out
    o.max_triangles = integer_in(name, v, 1, kMaxTriangleBudget, "the most triangles the mesh may have", shown);
  else  // eps-ties
    o.eps_ties =
        static_cast<int>(integer_in(name, v, 0, kMaxTieClasses, "the tie classes refined at key = eps", shown));
}

bool is_real(std::string_view name) { return name == "iso" || name == "eps" || name == "delta" || name == "radius"; }
bool is_integer(std::string_view name) { return name == "max-triangles" || name == "eps-ties"; }

[[noreturn]] void unknown(std::string_view name) {
  throw OptionError(std::string(name.substr(0, kMaxValueChars)), "is not an extraction option");
}

}  // namespace

std::optional<double> parse_real(std::string_view text) {
  auto parse_one = [](std::string_view s) -> std::optional<double> {
    if (s.empty()) return std::nullopt;
    if (s.front() == '+') s.remove_prefix(1);
    double v = 0;
    const auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), v);
    if (ec != std::errc() || end != s.data() + s.size()) return std::nullopt;
    return v;
  };
  const size_t slash = text.find('/');
  if (slash == std::string_view::npos) return parse_one(text);
  const auto num = parse_one(text.substr(0, slash));
  const auto den = parse_one(text.substr(slash + 1));
  if (!num || !den || *den == 0) return std::nullopt;
  return *num / *den;
}

void set_extract_option(ExtractOptions& o, std::string_view name, std::string_view text) {
  if (is_real(name)) return set_real(o, name, parse_real(text), quoted(text));
  if (is_integer(name)) return set_integer(o, name, integer(text), quoted(text));
  if (name == "focus") {
    std::array<double, 3> p{};
    size_t at = 0;
    for (size_t a = 0; a < 3; ++a) {
      const size_t end = a < 2 ? text.find(',', at) : text.size();
      if (end == std::string_view::npos || (a == 2 && text.find(',', at) != std::string_view::npos))
        throw OptionError("focus", "must be three numbers X,Y,Z, got " + quoted(text));
      const std::string_view part = text.substr(at, end - at);
      p[a] = finite("focus", parse_real(part), quoted(part));
      at = end + 1;
    }
    focus_of(o).point = p;
  } else if (name == "topology") {
    const auto t = value_named(text, kTopologyModes);
    if (!t) throw OptionError("topology", "must be none, paper, preserve or simplify, got " + quoted(text));
    o.topology = *t;
  } else if (name == "weight") {
    const auto w = value_named(text, kWeights);
    if (!w) throw OptionError("weight", "must be interval, gradient or size, got " + quoted(text));
    o.weight = *w;
  } else if (name == "error") {
    const auto e = value_named(text, kErrorIndicators);
    if (!e) throw OptionError("error", "must be bound or surplus, got " + quoted(text));
    o.error = *e;
  } else {
    unknown(name);
  }
}

void set_extract_option(ExtractOptions& o, std::string_view name, double value) {
  if (is_real(name)) return set_real(o, name, value, quoted(value));
  if (is_integer(name)) {
    // A whole number given as a real one is that integer; 1.5 or 1e300 is not one.
    const bool whole = std::trunc(value) == value && std::abs(value) < 0x1p62;
    return set_integer(o, name, whole ? std::optional<int64_t>(static_cast<int64_t>(value)) : std::nullopt,
                       quoted(value));
  }
  set_extract_option(o, name, std::string_view(shortest(value)));  // a name's option: refused as its text
}

void set_extract_option(ExtractOptions& o, std::string_view name, int64_t value) {
  if (is_integer(name)) return set_integer(o, name, value, quoted(std::to_string(value)));
  if (is_real(name)) return set_real(o, name, static_cast<double>(value), quoted(std::to_string(value)));
  set_extract_option(o, name, std::string_view(std::to_string(value)));
}

void set_extract_focus(ExtractOptions& o, const std::array<double, 3>& point) {
  for (const double x : point) finite("focus", x, quoted(x));
  focus_of(o).point = point;
}

void finish_extract_options(ExtractOptions& o, const std::set<std::string>& given) {
  const auto has = [&](const char* name) { return given.count(name) > 0; };
  if (!has("iso")) throw OptionError("iso", "is required");
  if (o.topology != TopologyMode::simplify && (has("delta") || has("weight")))
    throw OptionError(has("delta") ? "delta" : "weight", "applies to topology simplify only");
  if (has("focus") != has("radius"))
    throw OptionError(has("focus") ? "radius" : "focus",
                      has("focus") ? "is required with focus" : "is required with radius");
  // A budget in simplify mode without a delta chooses delta too (ExtractOptions::auto_delta).
  o.auto_delta = o.topology == TopologyMode::simplify && o.max_triangles > 0 && !has("delta");
  o.validate();
}

ExtractOptions parse_extract_options(const std::vector<std::pair<std::string, std::string>>& given) {
  ExtractOptions o;
  std::set<std::string> seen;
  for (const auto& [name, text] : given) {
    if (text.size() > kMaxValueChars) throw OptionError(name, "is too long");
    if (!seen.insert(name).second) throw OptionError(name, "is given twice");
    set_extract_option(o, name, std::string_view(text));
  }
  finish_extract_options(o, seen);
  return o;
}

int parse_thread_count(std::string_view text) {
  const std::optional<int64_t> v = integer(text.substr(0, kMaxValueChars + 1));
  RunContext run;
  run.threads = v && *v >= INT_MIN && *v <= INT_MAX ? static_cast<int>(*v) : -1;
  try {
    run.validate();
  } catch (const OptionError& e) {  // its words, with the text typed
    throw OptionError("threads", e.message.substr(0, e.message.rfind(", got ")) + ", got " + quoted(text));
  }
  return run.threads;
}

}  // namespace isotope
