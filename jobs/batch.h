// Batch runs: a job over many scans. Each input gets its own container and report; a bad file becomes a failed
// entry of the summary and the others still run. Outputs appear all-or-nothing. With `resume`, an input whose
// container is complete and whose report carries the same settings fingerprint (settings that change the bytes,
// plus the input's path, size and modification time) is skipped; `force` redoes it.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "jobs/commands.h"
#include "jobs/report.h"
#include "jobs/config.h"
#include "jobs/shard.h"

namespace scanpress {

struct RunOptions {
  bool force = false;
  bool quiet = false;
  int threads = -1;            // >= 0 overrides the job's threads
  std::optional<Shard> shard;  // run only this shard's inputs and write its own summary (jobs/shard.h)
};

struct FileOutcome {
  enum class State { kOk, kSkipped, kFailed };
  std::string input, output, report;
  std::string picture;    // the error heat map (/measure/render), when it exists
  std::string subfolder;  // the input's subfolder ({dir} in output names)
  State state = State::kFailed;
  Status error;
  bool has_result = false;
  EncodeResult result;
  double seconds = 0;
  // What the container holds: from this run's result, or from the report of an output resume skipped.
  struct Counts {
    uint64_t vertices = 0, faces = 0, bytes = 0, tiles = 0, failed_tiles = 0;
    uint64_t input_bytes = 0;  // the input file's size on disk (compressed if it is)
    // The measured symmetric error relative to the diagonal, when measured (else < 0).
    double rms_relative = -1, max_relative = -1;
  };
  std::optional<Counts> counts;
  bool report_written = false;  // `report` exists and describes this output (written now, or skipped complete)
};

struct BatchResult {
  std::vector<FileOutcome> files;
  // 0 when every file is ok or skipped; else the most severe failure: 4 internal > 3 environment > 2 bad data.
  int exitCode() const;
};

// One file named by a job's inputs, with its subfolder: the directory that holds it relative to the root of the
// input that named it (a directory input: that directory; a glob: its components before the first wildcard; a
// plain file: none, ""). Never absolute, never holding `..`.
struct JobInput {
  std::string path;
  std::string dir;
};

// Files named by the job's inputs, sorted, without duplicates (the first input that names a file gives its
// subfolder). Globs may have wildcards (`*`, `?`, `[...]`) in any component, and `**` as a whole component
// matches any number of directories (symlinked directories are not followed); as in the shell, no wildcard matches
// a name that starts with a dot. Errors (kInvalidArgument, naming
// /inputs/N) for a glob or directory that yields no mesh file; a plain file name is taken as it is (a missing file
// fails later, as that file's entry).
Result<std::vector<JobInput>> expandInputs(const JobSettings& job);

// `{stem}` / `{name}` / `{dir}` substitution; stem is the file name without .zst and the mesh extension, dir the
// input's subfolder (`{dir}/` vanishes when it has none).
std::string outputName(const std::string& pattern, const std::string& input, const std::string& dir = "");

// Hex fingerprint of what determines an output's bytes, for resume.
std::string settingsFingerprint(const EncodeSettings& settings);

// `hooks`: tests only (jobs/pipeline.h). An exception while one input is encoded (out of memory, a bug) fails that
// input, as a report entry; the others still run and the summary is written.
Result<BatchResult> runJob(const JobSettings& job, const RunOptions& options, const PipelineHooks* hooks = nullptr);

// `run --merge`: joins the summaries its shards wrote in the output directory (all from one split: i/N for every
// i < N) into the job's summary. Errors: no shard summary, summaries of two splits, a shard's missing (its task did
// not finish: kIo, naming it). Inputs of the job that no shard covered are listed (`missing`, exit code 3).
Result<MergedSummary> mergeJobShards(const JobSettings& job);

}  // namespace scanpress
