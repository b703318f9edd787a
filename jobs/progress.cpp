#include "jobs/progress.h"

#include <unistd.h>

#include <cstdio>

namespace scanpress {

TerminalProgress::TerminalProgress(bool quiet, FILE* out, std::optional<bool> terminal, double log_interval)
    : enabled_(!quiet),
      terminal_(terminal.value_or(::isatty(::fileno(out)) == 1)),
      out_(out),
      log_interval_(log_interval) {}

TerminalProgress::~TerminalProgress() { clear(); }

void TerminalProgress::file(size_t index, size_t count, const std::string& name) {
  index_ = index;
  count_ = count;
  file_ = name;
  done_ = total_ = 0;
  triangles_ = 0;
  start_ = stage_start_ = last_draw_ = std::chrono::steady_clock::now();
  draw(true);
}

void TerminalProgress::stage(const char* name) {
  stage_ = name;
  stage_start_ = std::chrono::steady_clock::now();
  draw(true);
}

void TerminalProgress::tiles(uint32_t done, uint32_t total, uint64_t triangles_done) {
  done_ = done;
  total_ = total;
  triangles_ = triangles_done;
  draw(done == total);
}

// A log line: "[2/10] scan.ply: encode, tiles 12/40, 1.23 Mtri/s, ETA 35 s", every log_interval_ seconds.
void TerminalProgress::log() {
  const auto now = std::chrono::steady_clock::now();
  if (std::chrono::duration<double>(now - last_draw_).count() < log_interval_ || total_ == 0) return;
  last_draw_ = now;
  const double secs = std::chrono::duration<double>(now - start_).count();
  const double in_stage = std::chrono::duration<double>(now - stage_start_).count();
  char line[512];
  int n = std::snprintf(line, sizeof line, "[%zu/%zu] %s: %s, tiles %u/%u, %.2f Mtri/s", index_ + 1, count_,
                        file_.c_str(), stage_.c_str(), done_, total_, secs > 0 ? triangles_ / secs / 1e6 : 0.0);
  if (done_ > 0 && done_ < total_ && n > 0 && n < int(sizeof line))
    std::snprintf(line + n, sizeof line - n, ", ETA %.0f s", in_stage * (total_ - done_) / done_);
  std::fprintf(out_, "%s\n", line);
  std::fflush(out_);
}

void TerminalProgress::draw(bool force) {
  if (!enabled_) return;
  if (!terminal_) return log();
  const auto now = std::chrono::steady_clock::now();
  if (!force && now - last_draw_ < std::chrono::milliseconds(100)) return;
  last_draw_ = now;
  const double secs = std::chrono::duration<double>(now - start_).count();
  char line[512];
  int n = std::snprintf(line, sizeof line, "\r[%zu/%zu] %s: %s", index_ + 1, count_, file_.c_str(), stage_.c_str());
  if (total_ > 0 && n > 0 && n < int(sizeof line))
    std::snprintf(line + n, sizeof line - n, " tiles %u/%u, %.2f Mtri/s", done_, total_,
                  secs > 0 ? triangles_ / secs / 1e6 : 0.0);
  std::fprintf(out_, "%s\x1b[K", line);
  std::fflush(out_);
  drawn_ = true;
}

void TerminalProgress::clear() {
  if (!enabled_ || !terminal_ || !drawn_) return;
  std::fprintf(out_, "\r\x1b[K");
  std::fflush(out_);
  drawn_ = false;
}

}  // namespace scanpress
