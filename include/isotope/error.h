#pragma once
// The one exception type of the I/O boundary: its message is what the user reads, naming the file
// and what is wrong with it ("scan.isotope: brick 812 (band 0, brick 3 5 2): checksum mismatch").
#include <stdexcept>

namespace isotope {

struct IoError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

}  // namespace isotope
