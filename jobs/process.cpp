#include "jobs/process.h"

#include <malloc.h>
#include <sys/resource.h>

#include <cinttypes>
#include <cstdio>

namespace scanpress {

uint64_t peakRss() {
  if (std::FILE* f = std::fopen("/proc/self/status", "r")) {
    char line[256];
    uint64_t kb = 0;
    bool found = false;
    while (!found && std::fgets(line, sizeof line, f)) found = std::sscanf(line, "VmHWM: %" SCNu64 " kB", &kb) == 1;
    std::fclose(f);
    if (found) return kb * 1024;
  }
  struct rusage ru {};
  ::getrusage(RUSAGE_SELF, &ru);
  return static_cast<uint64_t>(ru.ru_maxrss) * 1024;
}

void tuneAllocator() {
  ::mallopt(M_MMAP_THRESHOLD, 32 << 20);
  ::mallopt(M_TRIM_THRESHOLD, 64 << 20);
}

}  // namespace scanpress
