// Helpers of the jobs-layer tests: running the scanpress binary, finding the shared scan set.
#pragma once

#include <sys/wait.h>

#include <cstdio>
#include <cstdlib>
#include <string>

#include "test_util.h"

namespace scanpress::testing {

// Runs the scanpress binary with `args` (shell words), capturing stdout and stderr; returns its exit code.
// `env`: shell assignments (NAME='value' ...) for the command.
inline int runScanpress(const std::string& args, std::string* out = nullptr, const std::string& env = "") {
  FILE* p = ::popen((env + " '" + SCANPRESS_BIN + "' " + args + " 2>&1").c_str(), "r");
  std::string text;
  char buf[4096];
  size_t n;
  while ((n = std::fread(buf, 1, sizeof buf, p)) > 0) text.append(buf, n);
  const int status = ::pclose(p);
  if (out) *out = text;
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

inline std::string sharedDataDir() {
  if (const char* env = std::getenv("SCANPRESS_DATA")) return env;
  return SCANPRESS_SHARED_DATA;
}

}  // namespace scanpress::testing
