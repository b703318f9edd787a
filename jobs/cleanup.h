// Temporaries that must not outlive the process: a registry of live temporary outputs (AtomicFile's
// `.NAME.tmp-PID-N`) and scratch directories, removed when SIGINT, SIGTERM or SIGHUP ends the process.
//
// The approach: the CLI calls installInterruptCleanup() first thing in main(), before any other thread
// exists. It blocks the three signals in the calling thread, so every thread started later (oneTBB's workers,
// Embree's) inherits the mask and none of them is ever interrupted, and it starts one thread that waits for
// them with sigwait(). That thread is not a signal handler: it runs in an ordinary context and may take the
// registry's mutex, allocate and call std::filesystem. On a signal it takes the mutex, removes every
// registered file and directory (with its contents), writes one line to stderr and ends the process with
// _exit(128 + signal): 130 for SIGINT, 143 for SIGTERM, 129 for SIGHUP. It never releases the mutex, and
// every temporary is created while holding it (createTracked, underRegistryLock), so a temporary either
// exists and is registered when cleanup runs, or is never created: none escapes. SIGKILL cannot be caught;
// its leftovers (temporaries named with a dead PID) are removed by the next job run in that output directory
// (removeStaleTemporaries, jobs/file_io.h).
//
// Without installInterruptCleanup() (library use, the tests) the registry still tracks, and signals keep
// their default action.
#pragma once

#include <cstdint>
#include <functional>
#include <string>

namespace scanpress {

enum class TrackedKind { kFile, kDirectory };

// Runs `create` holding the registry's lock; `create` makes a file or directory and returns its path, or ""
// when it failed (then nothing is registered and 0 is returned). Returns the registration's id.
uint64_t createTracked(TrackedKind kind, const std::function<std::string()>& create);

// Forgets a registration (the temporary was removed, or renamed into a final output). 0 is ignored.
void untrack(uint64_t id);

// Runs `fn` holding the registry's lock: for creating files inside a registered directory, so that none
// appears after cleanup removed the directory.
void underRegistryLock(const std::function<void()>& fn);

// How many temporaries are registered (for tests).
size_t trackedCount();

// Blocks SIGINT, SIGTERM and SIGHUP (those not ignored on entry, as under nohup) in the calling thread and
// starts the thread that cleans up and exits on them. Call once, from main(), before any other thread starts.
void installInterruptCleanup();

}  // namespace scanpress
