// The extraction's options (isotope/extract.h): the names of their values, and one validation of
// them and of a run context. Their text, as the faces take it, is the faces' (option_text).
#include "engine/extract/options.h"

#include <bit>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <limits>
#include <set>

namespace isotope {

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

void RunContext::validate() const {
  if (threads < 0 || threads > kMaxThreads)
    throw OptionError("threads", "must be an integer in 0 .. " + std::to_string(kMaxThreads) +
                                     " (0: all cores), got '" + std::to_string(threads) + "'");
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

std::string_view to_string(SimplificationWeight w) {
  switch (w) {
    case SimplificationWeight::interval: return "interval";
    case SimplificationWeight::gradient: return "gradient";
    case SimplificationWeight::size: return "size";
  }
  return "unknown";
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
