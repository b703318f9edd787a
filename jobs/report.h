// JSON documents that scanpress writes: encode reports and container descriptions (`info --json`).
#pragma once

#include <string>

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
// The batch summary: one entry per input with status, sizes, bits per vertex, time and error.
struct BatchResult;
std::string batchSummaryJson(const std::string& config_path, const BatchResult& batch);
// `info --json`: grid, counts, bytes and one entry per tile.
std::string containerInfoJson(const ContainerFile& file);
// `info` for people.
std::string containerInfoText(const ContainerFile& file);

}  // namespace scanpress
