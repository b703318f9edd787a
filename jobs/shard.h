// Splitting a batch across the tasks of a job array (Slurm `--array`, Kubernetes indexed jobs, or any engine that
// starts N copies with an index): each task runs `scanpress run JOB.json --shard i/N` (or reads its index from the
// environment), encodes its share of the inputs and writes its own summary; `scanpress run JOB.json --merge` then
// joins the shard summaries into the job's summary and names every input no shard covered.
//
// The split is deterministic: the job's sorted inputs are dealt, largest file first, to the shard with the fewest
// bytes so far (ties: the lower shard), so every task computes the same split and the shards are balanced by input
// size. Outputs are per input, so shards never write the same file; resume works per shard as for a whole job.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "engine/status.h"

namespace scanpress {

struct JobInput;

struct Shard {
  uint32_t index = 0;  // 0 <= index < count
  uint32_t count = 1;
};

// "i/N" with 0 <= i < N <= 65536 (kInvalidArgument naming `what` otherwise).
Result<Shard> parseShard(std::string_view text, std::string_view what);

// The shard of this task from its environment, when it runs in a job array: Slurm's SLURM_ARRAY_TASK_ID (counted
// from SLURM_ARRAY_TASK_MIN) of SLURM_ARRAY_TASK_COUNT, or Kubernetes' JOB_COMPLETION_INDEX of `count` (which
// Kubernetes does not export: from --shard-count). Nothing when neither is set; an error when they are set but
// unusable (an index past the count, Kubernetes without a count).
Result<std::optional<Shard>> shardFromEnvironment(std::optional<uint32_t> count);

// The inputs of `shard`, in input order (see the split above). `sizes[i]` is the size of inputs[i] in bytes.
std::vector<JobInput> shardInputs(const std::vector<JobInput>& inputs, const std::vector<uint64_t>& sizes,
                                  const Shard& shard);

// The summary file of a shard: "summary.json" -> "summary.shard-2-of-4.json".
std::string shardSummaryName(const std::string& summary_name, const Shard& shard);

}  // namespace scanpress
