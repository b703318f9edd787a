// Progress of an encode, on stderr. On a terminal: one line, rewritten in place at most ten times a second: the
// file, the stage, tiles done of total and triangles per second. Elsewhere (a batch log, a Slurm output file): a
// plain line every `log_interval` seconds while a file encodes (tiles done, Mtri/s, ETA), so that a long run shows
// life without flooding the log. Silent when asked to be quiet.
#pragma once

#include <chrono>
#include <cstdio>
#include <optional>
#include <string>

#include "jobs/commands.h"

namespace scanpress {

class TerminalProgress : public ProgressListener {
 public:
  // `out` and `terminal` (default: stderr, and whether it is a terminal) are for tests.
  explicit TerminalProgress(bool quiet, FILE* out = stderr, std::optional<bool> terminal = std::nullopt,
                            double log_interval = 10);
  ~TerminalProgress() override;
  bool enabled() const { return enabled_; }
  void file(size_t index, size_t count, const std::string& name);
  void stage(const char* name) override;
  void tiles(uint32_t done, uint32_t total, uint64_t triangles_done) override;
  void clear();

 private:
  void draw(bool force);
  void log();
  bool enabled_, terminal_;
  FILE* out_;
  double log_interval_;
  std::string file_, stage_;
  size_t index_ = 0, count_ = 0;
  uint32_t done_ = 0, total_ = 0;
  uint64_t triangles_ = 0;
  std::chrono::steady_clock::time_point start_, stage_start_, last_draw_;
  bool drawn_ = false;
};

}  // namespace scanpress
