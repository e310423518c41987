#pragma once
// Progress of a long step (a hierarchy built, a store converted), for a user watching a terminal.
#include <functional>

namespace isotope {

// Hears the fraction done, 0 .. 1, only growing, at most once per percent, one call at a time,
// from any thread.
using ProgressCallback = std::function<void(double fraction)>;

}  // namespace isotope
