// Progress on a terminal: one line, rewritten in place, at most ten times a second: the file, the stage, tiles
// done of total and triangles per second. Silent when stderr is not a terminal or when asked to be quiet.
#pragma once

#include <chrono>
#include <string>

#include "jobs/commands.h"

namespace scanpress {

class TerminalProgress : public ProgressListener {
 public:
  explicit TerminalProgress(bool quiet);
  ~TerminalProgress() override;
  bool enabled() const { return enabled_; }
  void file(size_t index, size_t count, const std::string& name);
  void stage(const char* name) override;
  void tiles(uint32_t done, uint32_t total, uint64_t triangles_done) override;
  void clear();

 private:
  void draw(bool force);
  bool enabled_;
  std::string file_, stage_;
  size_t index_ = 0, count_ = 0;
  uint32_t done_ = 0, total_ = 0;
  uint64_t triangles_ = 0;
  std::chrono::steady_clock::time_point start_, last_draw_;
  bool drawn_ = false;
};

}  // namespace scanpress
