#include "tools/serve_request.h"

#include <algorithm>
#include <cmath>
#include <set>

#include "tools/commands.h"

namespace isotope::tools {
namespace {

constexpr size_t kMaxValueChars = 128;  // longer than any number or point a user types

double real(const std::string& name, const std::string& text, bool non_negative) {
  const auto v = parse_real(text);
  if (!v || !std::isfinite(*v)) throw BadRequest(name + " must be a finite number, got '" + text + "'");
  if (non_negative && *v < 0) throw BadRequest(name + " must be >= 0, got '" + text + "'");
  return *v;
}

std::array<double, 3> point(const std::string& text) {
  std::array<double, 3> p{};
  size_t at = 0;
  for (size_t a = 0; a < 3; ++a) {
    const size_t end = a < 2 ? text.find(',', at) : text.size();
    if (end == std::string::npos || (a == 2 && text.find(',', at) != std::string::npos))
      throw BadRequest("focus must be three numbers X,Y,Z, got '" + text + "'");
    p[a] = real("focus", text.substr(at, end - at), false);
    at = end + 1;
  }
  return p;
}

bool valid_client(const std::string& c) {
  return !c.empty() && c.size() <= 64 && std::all_of(c.begin(), c.end(), [](char ch) {
    return (ch >= 'a' && ch <= 'z') || (ch >= 'A' && ch <= 'Z') || (ch >= '0' && ch <= '9') || ch == '_' || ch == '-';
  });
}

int64_t sequence_number(const std::string& text) {
  const auto v = parse_real(text);
  if (!v || text.find_first_not_of("0123456789") != std::string::npos || *v > 9007199254740991.0)
    throw BadRequest("seq must be an integer >= 0, got '" + text + "'");
  return static_cast<int64_t>(*v);
}

}  // namespace

ServeRequest parse_extract_request(const std::multimap<std::string, std::string>& params) {
  static const std::set<std::string> known = {"iso",   "eps",    "topology", "delta",  "weight",
                                              "error", "focus",  "radius",   "client", "seq"};
  std::map<std::string, std::string> p;
  for (const auto& [name, value] : params) {
    if (!known.count(name)) throw BadRequest("unknown parameter '" + name.substr(0, kMaxValueChars) + "'");
    if (value.size() > kMaxValueChars) throw BadRequest(name + " is too long");
    if (!p.emplace(name, value).second) throw BadRequest(name + " is given twice");
  }
  auto given = [&](const char* name) { return p.count(name) > 0; };

  ServeRequest r;
  ExtractOptions& o = r.options;
  if (!given("iso")) throw BadRequest("iso is required");
  const double iso = real("iso", p["iso"], false);
  o.iso = static_cast<float>(iso);
  if (!std::isfinite(o.iso)) throw BadRequest("iso is out of the float range: '" + p["iso"] + "'");
  if (given("eps")) o.eps = real("eps", p["eps"], true);
  if (given("topology")) {
    const auto t = parse_topology_mode(p["topology"]);
    if (!t) throw BadRequest("topology must be none, paper, preserve or simplify, got '" + p["topology"] + "'");
    o.topology = *t;
  }
  if (o.topology != TopologyMode::simplify && (given("delta") || given("weight")))
    throw BadRequest("delta and weight apply to topology=simplify only");
  if (given("delta")) o.delta = real("delta", p["delta"], true);
  if (given("weight")) {
    const auto w = parse_simplification_weight(p["weight"]);
    if (!w) throw BadRequest("weight must be interval, gradient or size, got '" + p["weight"] + "'");
    o.weight = *w;
  }
  if (given("error")) {
    const auto e = parse_error_indicator(p["error"]);
    if (!e) throw BadRequest("error must be bound or surplus, got '" + p["error"] + "'");
    o.error = *e;
  }
  if (given("focus") != given("radius")) throw BadRequest("focus and radius go together");
  if (given("focus")) {
    Focus f;
    f.point = point(p["focus"]);
    f.radius = real("radius", p["radius"], true);
    if (!(f.radius > 0)) throw BadRequest("radius must be > 0, got '" + p["radius"] + "'");
    o.focus = f;
  }
  if (given("client")) {
    if (!valid_client(p["client"])) throw BadRequest("client must be 1-64 characters of A-Z a-z 0-9 _ -");
    r.client = p["client"];
  }
  if (given("seq")) {
    if (r.client.empty()) throw BadRequest("seq needs client");
    r.seq = sequence_number(p["seq"]);
  }
  return r;
}

}  // namespace isotope::tools
