// Job files: JSON parsed and validated into typed settings. This is the only place scanpress parses JSON.
//
// Every error names the file and the JSON pointer of the offending value (e.g. `job.json: /codec/bits: must be
// an integer in [8, 24], got 30`), or the byte offset of a syntax error; errors are kInvalidArgument (exit 1).
// Unknown keys are errors (a typo must not silently fall back to a default). Relative paths in a job file are
// relative to the directory of the job file. configs/REFERENCE.md lists every key with its default and meaning.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "engine/status.h"
#include "jobs/commands.h"

namespace scanpress {

struct JobSettings {
  std::string config_path;          // the job file ("" when built from the command line)
  std::vector<std::string> inputs;  // files, directories and globs (`*`, `?` in the last path component)
  bool recursive = false;           // directories: descend into subdirectories
  std::string output_directory = ".";
  std::string output_name = "{stem}.spz";          // {stem}: file name without mesh extensions; {name}: file name
  std::string report_name = "{stem}.report.json";  // "" for no per-file report (then resume is off)
  std::string summary_name = "summary.json";       // batch summary in the output directory; "" for none
  std::string html_name;  // report.html of the summary (jobs/html_report.h) in the output directory; "" for none
  bool resume = true;     // skip inputs whose output is complete and was made with the same settings
  EncodeSettings encode;  // input and output are filled in per file
};

// Limits that the command line and job files share.
constexpr uint64_t kMinTileTriangles = 1024, kMaxTileTriangles = uint64_t(1) << 31;
constexpr uint64_t kMaxMeasureSamples = uint64_t(1) << 40;

Result<JobSettings> parseJobConfig(const std::string& json_text, const std::string& config_path);
Result<JobSettings> loadJobConfig(const std::string& path);

// The encode option --stages: NAME[:KEY=VALUE...][,NAME...], the same stages and keys as /stages in job files
// (e.g. "smooth:iterations=5:lambda=0.4:mu=-0.42"); errors name `option` and the stage's pointer.
Result<std::vector<StageSpec>> parseStagesOption(const std::string& text, const std::string& option);

// Every key the parser knows, as JSON pointers (for the reference test).
std::vector<std::string> knownConfigKeys();

// What an encode report says of a complete output: the settings fingerprint and what the container holds.
struct CompleteReport {
  std::string fingerprint;
  uint64_t vertices = 0, faces = 0, bytes = 0, tiles = 0;
  uint64_t input_bytes = 0;
  double rms_relative = -1, max_relative = -1;  // symmetric, when the report has a measurement
};
// The report at `report_path` when it describes a complete output and carries a fingerprint; nothing when it is
// missing, unreadable, incomplete or has none (resume then redoes the file).
std::optional<CompleteReport> readCompleteReport(const std::string& report_path);

// The job file named by the batch summary at `summary_path` ("job"), when there is a readable one.
std::optional<std::string> summaryJobPath(const std::string& summary_path);

}  // namespace scanpress
