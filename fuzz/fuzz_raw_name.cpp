// libFuzzer target: what isotope reads from a raw volume's name and from --dims/--type
// (the raw reader's naming rule): NAME_XxYxZ_TYPE.raw, "XxYxZ", a type name. Each either parses to dimensions
// that are all >= 1 and a known type, or is refused (nullopt); nothing else.
#include <cstdlib>
#include <string>

#include "io/volume/raw_reader.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  if (const auto layout = isotope::parse_raw_name(text))
    for (int64_t d : layout->dims)
      if (d < 1) std::abort();
  if (const auto dims = isotope::parse_dims(text))
    for (int64_t d : *dims)
      if (d < 1) std::abort();
  (void)isotope::parse_scalar_type(text);
  return 0;
}
