#pragma once
// An extraction asked for over HTTP (docs/SERVE.md, GET /api/extract), checked as strictly as the
// command line checks `isotope extract`: any parameter that is unknown, repeated, malformed or out
// of range is refused with a message for the user, before any work starts.
#include <cstdint>
#include <map>
#include <optional>
#include <stdexcept>
#include <string>

#include "engine/extract/options.h"

namespace isotope::tools {

// HTTP 400: the message names the parameter and what it must be.
struct BadRequest : std::runtime_error {
  using std::runtime_error::runtime_error;
};

struct ServeRequest {
  ExtractOptions options;
  std::string client;          // "" when not given
  std::optional<int64_t> seq;  // with client: the request's number within it
};

// `params` as the HTTP library decodes a query string (name -> value, repeats kept).
// Throws BadRequest.
ServeRequest parse_extract_request(const std::multimap<std::string, std::string>& params);

}  // namespace isotope::tools
