// Names of the extraction choices, as the command line and the reports spell them.
#include "engine/options.h"

namespace isotope {

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
  if (o.eps == 0 && o.max_triangles == 0) return f;
  f.exact = o.topology == TopologyMode::preserve || o.topology == TopologyMode::simplify;
  f.weights = o.topology == TopologyMode::simplify;
  f.paper = o.topology == TopologyMode::paper;
  f.surplus = o.error == ErrorIndicator::surplus;
  return f;
}

}  // namespace isotope
