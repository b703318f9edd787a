// Fuzz target: the job-file parser (JSON syntax, every key's validation, stage lists). The input is the
// file's text; nothing is read or written (parseJobConfig only resolves relative paths against the job file's
// name).
#include <cstddef>
#include <cstdint>
#include <string>

#include "jobs/config.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  (void)scanpress::parseJobConfig(text, "/fuzz/job.json");
  return 0;
}
