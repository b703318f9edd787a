// Facts about this process.
#pragma once

#include <cstdint>

namespace scanpress {

// This process's peak resident set in bytes. Linux's VmHWM belongs to the running program image alone;
// getrusage's ru_maxrss also keeps, across exec, the resident set of the process that spawned it (a test binary
// of 120 MB launching scanpress), so it is only the fallback.
uint64_t peakRss();

// Sets glibc malloc's thresholds for a process that encodes tiles (the scanpress CLI and MPI workers call it first
// thing). glibc serves allocations from 128 KiB up with mmap, and raises that threshold only after the process frees
// such a block: tile tasks' large temporary arrays were mapped, faulted in and unmapped tile after tile unless an
// earlier step happened to free a large block (10^7 triangles: 1.47x the time on one thread, twice the tile time on
// an MPI worker). A fixed 32 MiB (glibc's own upper bound for its dynamic threshold) and a 64 MiB trim threshold
// make the speed independent of that history (bench/RESULTS.md, "Encode on two threads").
void tuneAllocator();

}  // namespace scanpress
