#include "tools/serve/serve_request.h"

#include <algorithm>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include "tools/support/option_text.h"

namespace isotope::tools {
namespace {

// The extraction options a client may set (docs/SERVE.md); the rest of ExtractOptions' are the
// command line's.
const std::set<std::string> kServedOptions = {"iso",   "eps",   "topology", "delta",         "weight",
                                              "error", "focus", "radius",   "max-triangles", "eps-ties"};

bool valid_client(const std::string& c) {
  return !c.empty() && c.size() <= 64 && std::all_of(c.begin(), c.end(), [](char ch) {
    return (ch >= 'a' && ch <= 'z') || (ch >= 'A' && ch <= 'Z') || (ch >= '0' && ch <= '9') || ch == '_' || ch == '-';
  });
}

int64_t sequence_number(const std::string& text) {
  const auto v = parse_real(text);
  if (!v || text.find_first_not_of("0123456789") != std::string::npos || *v > 9007199254740991.0)
    throw BadRequest("seq must be an integer >= 0, got '" + text.substr(0, 32) + "'");
  return static_cast<int64_t>(*v);
}

}  // namespace

ServeRequest parse_extract_request(const std::multimap<std::string, std::string>& params) {
  // client and seq are the server's own; everything else is an extraction option, read by the
  // reader every face shares (option_text), whose message names the parameter.
  ServeRequest r;
  std::vector<std::pair<std::string, std::string>> options;
  std::optional<std::string> client, seq;
  for (const auto& [name, value] : params) {
    if (name == "client" || name == "seq") {
      std::optional<std::string>& slot = name == "client" ? client : seq;
      if (slot) throw BadRequest(name + " is given twice");
      slot = value;
    } else if (kServedOptions.count(name)) {
      options.emplace_back(name, value);
    } else {
      throw BadRequest("unknown parameter '" + name.substr(0, 64) + "'");
    }
  }
  try {
    r.options = parse_extract_options(options);
  } catch (const OptionError& e) {
    throw BadRequest(e.what());
  }
  if (client) {
    if (!valid_client(*client)) throw BadRequest("client must be 1-64 characters of A-Z a-z 0-9 _ -");
    r.client = *client;
  }
  if (seq) {
    if (r.client.empty()) throw BadRequest("seq needs client");
    r.seq = sequence_number(*seq);
  }
  return r;
}

}  // namespace isotope::tools
