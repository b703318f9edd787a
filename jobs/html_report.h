// report.html: a batch summary (summary.json, jobs/report.h) as one page people read in a browser without a
// server: a sortable table of every scan (sizes, bits per vertex, ratio, measured error, time, tiles, status) with a
// thumbnail of each decoded container (rendered here, embedded as a data URI, so the page is one file) and the
// error heat map the job rendered (/measure/render), linked relative to the page.
#pragma once

#include "jobs/commands.h"

#include <memory>
#include <string>

#include "engine/status.h"

namespace scanpress {

class EmbreeDevice;

struct HtmlReportOptions {
  bool thumbnails = true;  // decode and render each container (the slow part: a decode per scan)
  int thumbnail_width = 240, thumbnail_height = 180;
  // A container whose in-memory decode would need more is drawn from a vertex-clustered decode instead (its shape
  // at thumbnail resolution, jobs/stream_decode.h), within the budget (0: no limit).
  uint64_t memory_budget = kDefaultDecodeBudget;
};

// Reads the summary at `summary_path` and writes `html_path` all-or-nothing. Containers and pictures are found
// from the paths the summary holds (as written, else relative to the summary's folder). A container that cannot
// be decoded gets a note in its row, not a failure; an unreadable or malformed summary is an error naming it.
Status writeHtmlReport(const std::string& summary_path, const std::string& html_path, const HtmlReportOptions& options,
                       std::shared_ptr<EmbreeDevice> device = nullptr);

// `path` names a summary, or a directory holding `summary.json`: the summary's path (the input when neither).
std::string summaryPathOf(const std::string& path);

}  // namespace scanpress
