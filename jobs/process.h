// Facts about this process.
#pragma once

#include <cstdint>

namespace scanpress {

// This process's peak resident set in bytes. Linux's VmHWM belongs to the running program image alone;
// getrusage's ru_maxrss also keeps, across exec, the resident set of the process that spawned it (a test binary
// of 120 MB launching scanpress), so it is only the fallback.
uint64_t peakRss();

}  // namespace scanpress
