#include "jobs/progress.h"

#include <unistd.h>

#include <cstdio>

namespace scanpress {

TerminalProgress::TerminalProgress(bool quiet) : enabled_(!quiet && ::isatty(STDERR_FILENO)) {}

TerminalProgress::~TerminalProgress() { clear(); }

void TerminalProgress::file(size_t index, size_t count, const std::string& name) {
  index_ = index;
  count_ = count;
  file_ = name;
  done_ = total_ = 0;
  triangles_ = 0;
  start_ = std::chrono::steady_clock::now();
  draw(true);
}

void TerminalProgress::stage(const char* name) {
  stage_ = name;
  draw(true);
}

void TerminalProgress::tiles(uint32_t done, uint32_t total, uint64_t triangles_done) {
  done_ = done;
  total_ = total;
  triangles_ = triangles_done;
  draw(done == total);
}

void TerminalProgress::draw(bool force) {
  if (!enabled_) return;
  const auto now = std::chrono::steady_clock::now();
  if (!force && now - last_draw_ < std::chrono::milliseconds(100)) return;
  last_draw_ = now;
  const double secs = std::chrono::duration<double>(now - start_).count();
  char line[512];
  int n = std::snprintf(line, sizeof line, "\r[%zu/%zu] %s: %s", index_ + 1, count_, file_.c_str(), stage_.c_str());
  if (total_ > 0 && n > 0 && n < int(sizeof line))
    std::snprintf(line + n, sizeof line - n, " tiles %u/%u, %.2f Mtri/s", done_, total_,
                  secs > 0 ? triangles_ / secs / 1e6 : 0.0);
  std::fprintf(stderr, "%s\x1b[K", line);
  std::fflush(stderr);
  drawn_ = true;
}

void TerminalProgress::clear() {
  if (!enabled_ || !drawn_) return;
  std::fprintf(stderr, "\r\x1b[K");
  std::fflush(stderr);
  drawn_ = false;
}

}  // namespace scanpress
