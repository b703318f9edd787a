// `-` as a file name: standard input for a command's input, standard output for its output (encode, decode and
// `--report`), as Unix tools do.
//
// Both ends go through a private scratch directory: the encoder reads a mesh twice (survey, then ingest) and a
// container is read from its end (footer, index), so stdin is copied to a file first; and outputs appear all or
// nothing, so an output is written whole to a file and then copied to stdout (nothing reaches stdout when the
// command fails). The directory is registered with jobs/cleanup.h: removed when the command ends, and on SIGINT,
// SIGTERM or SIGHUP.
#pragma once

#include <cstdint>
#include <string>

#include "engine/status.h"

namespace scanpress {

inline bool isStdio(const std::string& name) { return name == "-"; }

class StdioSpool {
 public:
  // A fresh directory `scanpress-stdio-PID-N` under `parent` (empty: the system's temporary directory).
  static Result<StdioSpool> create(const std::string& parent = "");
  StdioSpool(StdioSpool&& other) noexcept;
  StdioSpool& operator=(StdioSpool&&) = delete;
  StdioSpool(const StdioSpool&) = delete;
  ~StdioSpool();

  // The path of `name` in the directory.
  std::string path(const std::string& name) const;
  // Copies all of stdin into `name`; returns its path. An empty stdin is copied as an empty file (the reader
  // then names what is missing).
  Result<std::string> readStdin(const std::string& name);
  // Copies `name` to stdout and flushes it (kIo when stdout fails: a closed pipe, a full disk).
  Status writeStdout(const std::string& name) const;

 private:
  StdioSpool(std::string dir, uint64_t tracked) : dir_(std::move(dir)), tracked_(tracked) {}
  std::string dir_;
  uint64_t tracked_ = 0;
};

}  // namespace scanpress
