#include "jobs/shard.h"

#include <algorithm>
#include <cstdlib>
#include <numeric>

#include "jobs/batch.h"
#include "jobs/numbers.h"

namespace scanpress {

constexpr uint32_t kMaxShards = 65536;

Result<Shard> parseShard(std::string_view text, std::string_view what) {
  const size_t slash = text.find('/');
  auto bad = [&] {
    return makeError(ErrorCode::kInvalidArgument,
                     std::string(what) + ": must be i/N with 0 <= i < N <= " + std::to_string(kMaxShards) + ", got '" +
                         std::string(text) + "'");
  };
  if (slash == std::string_view::npos) return bad();
  auto i = parseUnsigned(text.substr(0, slash), kMaxShards - 1, what);
  auto n = parseUnsigned(text.substr(slash + 1), kMaxShards, what);
  if (!i.isOk() || !n.isOk() || *n == 0 || *i >= *n) return bad();
  return Shard{static_cast<uint32_t>(*i), static_cast<uint32_t>(*n)};
}

Result<std::optional<Shard>> shardFromEnvironment(std::optional<uint32_t> count) {
  auto env = [](const char* name) -> std::optional<std::string> {
    const char* v = std::getenv(name);
    return v && *v ? std::optional<std::string>(v) : std::nullopt;
  };
  if (auto id = env("SLURM_ARRAY_TASK_ID")) {
    auto task = parseUnsigned(*id, UINT32_MAX, "SLURM_ARRAY_TASK_ID");
    if (!task.isOk()) return task.status();
    uint64_t min = 0;
    if (auto m = env("SLURM_ARRAY_TASK_MIN")) {
      auto parsed = parseUnsigned(*m, UINT32_MAX, "SLURM_ARRAY_TASK_MIN");
      if (!parsed.isOk()) return parsed.status();
      min = *parsed;
    }
    uint64_t n = count.value_or(0);
    if (auto c = env("SLURM_ARRAY_TASK_COUNT"); c && !count) {
      auto parsed = parseUnsigned(*c, kMaxShards, "SLURM_ARRAY_TASK_COUNT");
      if (!parsed.isOk()) return parsed.status();
      n = *parsed;
    }
    if (n == 0)
      return makeError(ErrorCode::kInvalidArgument,
                       "SLURM_ARRAY_TASK_ID is set but SLURM_ARRAY_TASK_COUNT is not: give --shard-count N");
    // A stepped array (--array=0-15:4) has ids that are not consecutive: refuse it rather than miss inputs.
    if (*task < min || *task - min >= n)
      return makeError(ErrorCode::kInvalidArgument,
                       "SLURM_ARRAY_TASK_ID " + *id + " is not in [SLURM_ARRAY_TASK_MIN, MIN + COUNT) = [" +
                           std::to_string(min) + ", " + std::to_string(min + n) +
                           "): use a consecutive array (--array=0-" + std::to_string(n - 1) + ") or --shard i/N");
    return std::optional<Shard>(Shard{static_cast<uint32_t>(*task - min), static_cast<uint32_t>(n)});
  }
  if (auto index = env("JOB_COMPLETION_INDEX")) {
    if (!count)
      return makeError(ErrorCode::kInvalidArgument,
                       "JOB_COMPLETION_INDEX is set (a Kubernetes indexed job): give --shard-count N, its completions");
    auto i = parseUnsigned(*index, UINT32_MAX, "JOB_COMPLETION_INDEX");
    if (!i.isOk()) return i.status();
    if (*i >= *count)
      return makeError(ErrorCode::kInvalidArgument,
                       "JOB_COMPLETION_INDEX " + *index + " is not below --shard-count " + std::to_string(*count));
    return std::optional<Shard>(Shard{static_cast<uint32_t>(*i), *count});
  }
  if (count)
    return makeError(ErrorCode::kInvalidArgument,
                     "--shard-count needs a job array's index in the "
                     "environment (SLURM_ARRAY_TASK_ID or JOB_COMPLETION_INDEX)");
  return std::optional<Shard>();
}

std::vector<JobInput> shardInputs(const std::vector<JobInput>& inputs, const std::vector<uint64_t>& sizes,
                                  const Shard& shard) {
  std::vector<size_t> order(inputs.size());
  std::iota(order.begin(), order.end(), size_t{0});
  // Largest first; equal sizes in input order. Inputs are sorted by path, so the deal is the same in every task.
  std::stable_sort(order.begin(), order.end(), [&](size_t a, size_t b) { return sizes[a] > sizes[b]; });
  std::vector<uint64_t> load(shard.count, 0);
  std::vector<uint8_t> mine(inputs.size(), 0);
  for (size_t i : order) {
    const size_t s = std::min_element(load.begin(), load.end()) - load.begin();
    load[s] += std::max<uint64_t>(sizes[i], 1);  // an empty or missing file still counts as work
    mine[i] = s == shard.index;
  }
  std::vector<JobInput> out;
  for (size_t i = 0; i < inputs.size(); ++i)
    if (mine[i]) out.push_back(inputs[i]);
  return out;
}

std::string shardSummaryName(const std::string& summary_name, const Shard& shard) {
  const std::string tag = ".shard-" + std::to_string(shard.index) + "-of-" + std::to_string(shard.count);
  const size_t dot = summary_name.rfind('.');
  if (dot == std::string::npos || dot == 0) return summary_name + tag;
  return summary_name.substr(0, dot) + tag + summary_name.substr(dot);
}

}  // namespace scanpress
