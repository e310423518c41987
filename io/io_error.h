#pragma once
// The one exception type of the I/O boundary: its message is what the user reads.
#include <stdexcept>

namespace isotope {

struct IoError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

}  // namespace isotope
