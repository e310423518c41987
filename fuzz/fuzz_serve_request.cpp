// libFuzzer target: the query string of GET /api/extract as `isotope serve` takes it (docs/SERVE.md):
// decoded by cpp-httplib, then checked as the server checks a request. Every refusal must be a
// BadRequest (HTTP 400 with its message); an accepted request must hold options the engine accepts.
#include <httplib.h>

#include <cmath>
#include <cstdlib>
#include <string>

#include "tools/serve/serve_request.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string query(reinterpret_cast<const char*>(data), size);
  httplib::Params params;
  httplib::detail::parse_query_text(query, params);
  try {
    const isotope::tools::ServeRequest r = isotope::tools::parse_extract_request(params);
    if (!std::isfinite(r.options.iso) || !std::isfinite(r.options.eps) || r.options.eps < 0 || r.options.delta < 0)
      std::abort();
  } catch (const isotope::tools::BadRequest&) {
  }
  return 0;
}
