// The extraction's options (isotope/extract.h): their names as every face spells them, one text
// parser, and one validation.
#include "engine/extract/options.h"

#include <bit>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <limits>
#include <optional>
#include <set>

namespace isotope {
namespace {

constexpr size_t kMaxValueChars = 128;  // longer than any number or point a user types

std::string quoted(std::string_view text) {
  return "'" + std::string(text.substr(0, kMaxValueChars)) + (text.size() > kMaxValueChars ? "...'" : "'");
}

double finite_real(std::string_view name, std::string_view text) {
  const auto v = parse_real(text);
  if (!v || !std::isfinite(*v)) throw OptionError(std::string(name), "must be a finite number, got " + quoted(text));
  return *v;
}

double non_negative_real(std::string_view name, std::string_view text) {
  const double v = finite_real(name, text);
  if (v < 0) throw OptionError(std::string(name), "must be >= 0, got " + quoted(text));
  return v;
}

std::array<double, 3> point(std::string_view text) {
  std::array<double, 3> p{};
  size_t at = 0;
  for (size_t a = 0; a < 3; ++a) {
    const size_t end = a < 2 ? text.find(',', at) : text.size();
    if (end == std::string_view::npos || (a == 2 && text.find(',', at) != std::string_view::npos))
      throw OptionError("focus", "must be three numbers X,Y,Z, got " + quoted(text));
    p[a] = finite_real("focus", text.substr(at, end - at));
    at = end + 1;
  }
  return p;
}

// An integer as typed, within [lo, hi]; nullopt otherwise (not a whole number, out of range,
// beyond 64 bits).
std::optional<int64_t> integer_in(std::string_view text, int64_t lo, int64_t hi) {
  if (!text.empty() && text.front() == '+') text.remove_prefix(1);
  int64_t v = 0;
  const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), v);
  if (ec != std::errc() || end != text.data() + text.size() || v < lo || v > hi) return std::nullopt;
  return v;
}

int64_t triangle_budget(std::string_view text) {
  // 0 would mean no budget, which is leaving the option out: a budget of 0 is refused as meaningless.
  const auto v = integer_in(text, 1, kMaxTriangleBudget);
  if (!v)
    throw OptionError("max-triangles", "must be an integer in 1 .. " + std::to_string(kMaxTriangleBudget) +
                                           " (the most triangles the mesh may have), got " + quoted(text));
  return *v;
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
  if (name == "iso") {
    const double iso = finite_real(name, text);
    o.iso = static_cast<float>(iso);
    if (!std::isfinite(o.iso)) throw OptionError("iso", "is out of the float range: " + quoted(text));
  } else if (name == "eps") {
    o.eps = non_negative_real(name, text);
  } else if (name == "delta") {
    o.delta = non_negative_real(name, text);
  } else if (name == "radius") {
    const double r = finite_real(name, text);
    if (!(r > 0)) throw OptionError("radius", "must be > 0, got " + quoted(text));
    if (!o.focus) o.focus = Focus{};
    o.focus->radius = r;
  } else if (name == "focus") {
    const auto p = point(text);
    if (!o.focus) o.focus = Focus{};
    o.focus->point = p;
  } else if (name == "topology") {
    const auto t = parse_topology_mode(text);
    if (!t) throw OptionError("topology", "must be none, paper, preserve or simplify, got " + quoted(text));
    o.topology = *t;
  } else if (name == "weight") {
    const auto w = parse_simplification_weight(text);
    if (!w) throw OptionError("weight", "must be interval, gradient or size, got " + quoted(text));
    o.weight = *w;
  } else if (name == "error") {
    const auto e = parse_error_indicator(text);
    if (!e) throw OptionError("error", "must be bound or surplus, got " + quoted(text));
    o.error = *e;
  } else if (name == "max-triangles") {
    o.max_triangles = triangle_budget(text);
  } else if (name == "eps-ties") {
    const auto v = integer_in(text, 0, kMaxTieClasses);
    if (!v)
      throw OptionError("eps-ties", "must be an integer in 0 .. " + std::to_string(kMaxTieClasses) +
                                        " (the tie classes refined at key = eps), got " + quoted(text));
    o.eps_ties = static_cast<int>(*v);
  } else {
    throw OptionError(std::string(name.substr(0, kMaxValueChars)), "is not an extraction option");
  }
}

ExtractOptions parse_extract_options(const std::vector<std::pair<std::string, std::string>>& given) {
  ExtractOptions o;
  std::set<std::string> seen;
  for (const auto& [name, text] : given) {
    if (text.size() > kMaxValueChars) throw OptionError(name, "is too long");
    if (!seen.insert(name).second) throw OptionError(name, "is given twice");
    set_extract_option(o, name, text);
  }
  const auto has = [&](const char* name) { return seen.count(name) > 0; };
  if (!has("iso")) throw OptionError("iso", "is required");
  if (o.topology != TopologyMode::simplify && (has("delta") || has("weight")))
    throw OptionError(has("delta") ? "delta" : "weight", "applies to topology simplify only");
  if (has("focus") != has("radius"))
    throw OptionError(has("focus") ? "radius" : "focus",
                      has("focus") ? "is required with focus" : "is required with radius");
  // A budget in simplify mode without a delta chooses delta too (isotope/extract.h, auto_delta).
  o.auto_delta = o.topology == TopologyMode::simplify && o.max_triangles > 0 && !has("delta");
  o.validate();
  return o;
}

void ExtractOptions::validate() const {
  if (!std::isfinite(iso)) throw OptionError("iso", "must be a finite number");
  // Infinity is allowed here (the coarsest mesh the mode allows; every weight under delta), not
  // in text, where it is more likely a typo than a wish.
  if (!(eps >= 0)) throw OptionError("eps", "must be >= 0");
  if (!(delta >= 0)) throw OptionError("delta", "must be >= 0");
  if (delta > 0 && topology != TopologyMode::simplify) throw OptionError("delta", "applies to topology simplify only");
  if (max_triangles < 0 || max_triangles > kMaxTriangleBudget)
    throw OptionError("max-triangles", "must be in 0 .. " + std::to_string(kMaxTriangleBudget));
  if (max_triangles > 0 && eps != 0)
    throw OptionError("max-triangles", "chooses eps itself: give eps or max-triangles, not both");
  if (eps_ties < -1 || eps_ties > kMaxTieClasses)
    throw OptionError("eps-ties", "must be in 0 .. " + std::to_string(kMaxTieClasses));
  if (eps_ties >= 0 && max_triangles > 0)
    throw OptionError("eps-ties", "is chosen by max-triangles: give eps-ties with eps only");
  if (eps_ties >= 0 && !std::isfinite(eps)) throw OptionError("eps-ties", "applies to a finite eps only");
  if (auto_delta && (topology != TopologyMode::simplify || max_triangles == 0 || delta != 0))
    throw OptionError("delta", "is chosen only with topology simplify, a triangle budget and no delta given");
  if (focus) {
    if (!std::isfinite(focus->point[0]) || !std::isfinite(focus->point[1]) || !std::isfinite(focus->point[2]))
      throw OptionError("focus", "must be a finite point");
    if (!(focus->radius > 0) || !std::isfinite(focus->radius))
      throw OptionError("radius", "must be a finite number > 0");
  }
}

namespace {
std::string threads_must_be() {
  return "must be an integer in 0 .. " + std::to_string(kMaxThreads) + " (0: all cores)";
}
}  // namespace

void RunContext::validate() const {
  if (threads < 0 || threads > kMaxThreads)
    throw OptionError("threads", threads_must_be() + ", got " + std::to_string(threads));
}

int parse_thread_count(std::string_view text) {
  const auto v = integer_in(text.substr(0, kMaxValueChars + 1), 0, kMaxThreads);
  if (!v) throw OptionError("threads", threads_must_be() + ", got " + quoted(text));
  return static_cast<int>(*v);
}

std::string_view to_string(ErrorIndicator e) {
  switch (e) {
    case ErrorIndicator::bound: return "bound";
    case ErrorIndicator::surplus: return "surplus";
  }
  return "unknown";
}

std::string_view to_string(TopologyMode t) {
  switch (t) {
    case TopologyMode::none: return "none";
    case TopologyMode::paper: return "paper";
    case TopologyMode::preserve: return "preserve";
    case TopologyMode::simplify: return "simplify";
  }
  return "unknown";
}

std::optional<ErrorIndicator> parse_error_indicator(std::string_view s) {
  if (s == "bound") return ErrorIndicator::bound;
  if (s == "surplus") return ErrorIndicator::surplus;
  return std::nullopt;
}

std::optional<TopologyMode> parse_topology_mode(std::string_view s) {
  if (s == "none") return TopologyMode::none;
  if (s == "paper") return TopologyMode::paper;
  if (s == "preserve") return TopologyMode::preserve;
  if (s == "simplify") return TopologyMode::simplify;
  return std::nullopt;
}

std::string_view to_string(SimplificationWeight w) {
  switch (w) {
    case SimplificationWeight::interval: return "interval";
    case SimplificationWeight::gradient: return "gradient";
    case SimplificationWeight::size: return "size";
  }
  return "unknown";
}

std::optional<SimplificationWeight> parse_simplification_weight(std::string_view s) {
  if (s == "interval") return SimplificationWeight::interval;
  if (s == "gradient") return SimplificationWeight::gradient;
  if (s == "size") return SimplificationWeight::size;
  return std::nullopt;
}

RecordFields fields_for(const ExtractOptions& o) {
  RecordFields f{false, false, false, false};
  if (o.eps == 0 && o.max_triangles == 0 && o.eps_ties < 0) return f;  // full resolution: values only
  f.exact = o.topology == TopologyMode::preserve || o.topology == TopologyMode::simplify;
  f.weights = o.topology == TopologyMode::simplify;
  f.paper = o.topology == TopologyMode::paper;
  f.surplus = o.error == ErrorIndicator::surplus;
  return f;
}

double threshold_in_codes(double value, double factor) {
  const double quotient = value / factor;
  if (!std::isfinite(quotient) || quotient == 0) return quotient;
  auto trailing_zeros = [](double x) {  // of the significand: 52 for a power of two
    constexpr uint64_t kSignificand = (uint64_t{1} << 52) - 1;
    return std::countr_zero((std::bit_cast<uint64_t>(x) & kSignificand) | (uint64_t{1} << 52));
  };
  // The doubles whose product rounds to `value` lie within a few ulps of the quotient. One of
  // them replaces the quotient only when it is clearly rounder: a key with arbitrary low bits (a
  // focus divides the error by its factor) keeps the quotient, as before.
  constexpr int kReach = 4, kRounder = 16;
  constexpr double kInf = std::numeric_limits<double>::infinity();
  double x = quotient;
  for (int i = 0; i < kReach; ++i) x = std::nextafter(x, -kInf);
  double best = quotient;
  int best_zeros = trailing_zeros(quotient) + kRounder;
  for (int i = 0; i <= 2 * kReach; ++i, x = std::nextafter(x, kInf)) {
    if (x * factor != value) continue;
    const int zeros = trailing_zeros(x);
    if (zeros > best_zeros) best = x, best_zeros = zeros;
  }
  return best;
}

}  // namespace isotope
