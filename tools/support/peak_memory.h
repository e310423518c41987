#pragma once
// The process's peak resident memory, measurable over one stretch of work: the kernel keeps a
// high-water mark (VmHWM) that Linux >= 4.0 lets a process reset, so a benchmark can report
// the peak of each case it runs instead of the peak of the whole run.
#include <cstdint>

namespace isotope::tools {

// Resets the high-water mark to the current resident size. False where the kernel does not
// allow it (then peak_rss_bytes() keeps measuring from the start of the process).
bool reset_peak_rss();

// The high-water mark of resident memory since the start or the last successful reset, in bytes.
uint64_t peak_rss_bytes();

}  // namespace isotope::tools
