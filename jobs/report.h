// JSON documents that scanpress writes: encode reports and container descriptions (`info --json`).
#pragma once

#include <string>
#include <vector>

#include "jobs/commands.h"
#include "jobs/container_file.h"

namespace scanpress {

// The encode report as JSON text (pretty-printed): counts, drops, bytes, bits per vertex, seconds per stage,
// threads, memory, and one entry per tile.
// `fingerprint` (settingsFingerprint) is stored for resume when the output is complete (no failed tile).
std::string encodeReportJson(const EncodeSettings& settings, const EncodeResult& result,
                             const std::string& fingerprint = "");
// `measure --json`: {"diagonal", "samples", "forward": {"mean", "rms", "max", "samples", "mean_relative",
// "rms_relative", "max_relative"}, "backward": {...}, "symmetric": {...}}.
std::string measureJson(const MeasureResult& r);
// The batch summary: one entry per input with status, sizes, bits per vertex, time and error, and totals; a
// shard's summary (jobs/shard.h) says which shard it is.
struct BatchResult;
struct Shard;
std::string batchSummaryJson(const std::string& config_path, const BatchResult& batch, const Shard* shard = nullptr);
// Merges the summaries of all `count` shards of the job `config_path` (paths in shard order; a missing file is an
// error naming its shard) into one batch summary (JSON text): files sorted by input, totals over them, the worst
// exit code. `expected_inputs`: the job's inputs; those in no shard summary are returned in `missing`.
struct MergedSummary {
  std::string json;
  uint64_t files = 0;
  int exit_code = 0;
  std::vector<std::string> missing;
};
Result<MergedSummary> mergeShardSummaries(const std::string& config_path, const std::vector<std::string>& shard_paths,
                                          const std::vector<std::string>& expected_inputs);
// `info --json`: grid, counts, bytes and one entry per tile.
std::string containerInfoJson(const ContainerFile& file);
// `info` for people.
std::string containerInfoText(const ContainerFile& file);

}  // namespace scanpress
