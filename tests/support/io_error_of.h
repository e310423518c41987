#pragma once
// The message of the IoError a call throws; a test failure when it throws nothing.
#include <gtest/gtest.h>

#include <functional>
#include <string>

#include "isotope/error.h"

namespace isotope::testing {

inline std::string io_error_of(const std::function<void()>& f) {
  try {
    f();
  } catch (const IoError& e) {
    return e.what();
  }
  ADD_FAILURE() << "expected an IoError";
  return "";
}

}  // namespace isotope::testing
