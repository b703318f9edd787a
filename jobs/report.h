// JSON documents that scanpress writes: encode reports and container descriptions (`info --json`).
#pragma once

#include <string>

#include "jobs/commands.h"
#include "jobs/container_file.h"

namespace scanpress {

// The encode report as JSON text (pretty-printed): counts, drops, bytes, bits per vertex, seconds per stage,
// threads, memory, and one entry per tile.
std::string encodeReportJson(const EncodeSettings& settings, const EncodeResult& result);
// `info --json`: grid, counts, bytes and one entry per tile.
std::string containerInfoJson(const ContainerFile& file);
// `info` for people.
std::string containerInfoText(const ContainerFile& file);

}  // namespace scanpress
