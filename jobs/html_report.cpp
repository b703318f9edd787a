// report.html: see jobs/html_report.h.
#include "jobs/html_report.h"

#include <nlohmann/json.hpp>

#include <cctype>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <vector>

#include "engine/quantize.h"
#include "jobs/base64.h"
#include "jobs/commands.h"
#include "jobs/container_file.h"
#include "jobs/file_io.h"
#include "jobs/numbers.h"
#include "jobs/render.h"
#include "jobs/stream_decode.h"
#include "spatial/surface_index.h"

namespace scanpress {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

std::string escape(const std::string& s) {
  std::string out;
  out.reserve(s.size());
  for (char c : s) switch (c) {
      case '&': out += "&amp;"; break;
      case '<': out += "&lt;"; break;
      case '>': out += "&gt;"; break;
      case '"': out += "&quot;"; break;
      case '\'': out += "&#39;"; break;
      default: out += c;
    }
  return out;
}

std::string format(const char* f, double v) {
  char b[64];
  std::snprintf(b, sizeof b, f, v);
  return b;
}

// A path from the summary: as written when it exists, else the same file name in the summary's folder (a summary
// moved with its outputs, or paths relative to another working directory).
std::string locate(const std::string& path, const fs::path& summary_dir) {
  std::error_code ec;
  if (path.empty() || fs::exists(path, ec)) return path;
  const fs::path beside = summary_dir / fs::path(path).filename();
  return fs::exists(beside, ec) ? beside.string() : "";
}

// Cluster cells per axis for the thumbnail of a scan too large to decode whole (at most 127: decodeClustered's
// triangle keys).
constexpr uint32_t kThumbnailCells = 120;

// The decoded container rendered as a PNG data URI, or a note saying why not.
std::string thumbnail(const std::string& container, const HtmlReportOptions& o,
                      const std::shared_ptr<EmbreeDevice>& device, std::string& note) {
  auto file = ContainerFile::open(container);
  if (!file.isOk()) return note = "not decodable: " + file.status().message(), "";
  std::vector<const TileEntry*> tiles;
  for (const TileEntry& e : file->tiles()) tiles.push_back(&e);
  Mesh mesh;
  if (o.memory_budget != 0 && inMemoryDecodeBytes(tiles) > o.memory_budget) {
    // Too large to decode whole within the budget: its shape at thumbnail resolution (a cell per 2 pixels).
    auto clustered = decodeClustered(*file, kThumbnailCells, o.memory_budget);
    if (!clustered.isOk()) return note = "not decodable: " + clustered.status().message(), "";
    mesh = std::move(clustered).value();
  } else {
    ContainerHeader header;
    auto q = decodeContainer(container, std::nullopt, &header);
    if (!q.isOk()) return note = "not decodable: " + q.status().message(), "";
    mesh = dequantizeMesh(*q, header.grid, header.layout);
  }
  if (mesh.triangles.empty()) return note = "no triangles", "";
  RenderSettings rs;
  rs.width = o.thumbnail_width;
  rs.height = o.thumbnail_height;
  auto picture = renderMesh(mesh, rs, device, nullptr);
  if (!picture.isOk()) return note = "not rendered: " + picture.status().message(), "";
  auto png = encodePng(picture->image);
  if (!png.isOk()) return note = png.status().message(), "";
  return "data:image/png;base64," + base64(*png);
}

// A numeric cell: the sort key in data-v, the text shown.
std::string cell(double v, const std::string& text) {
  return "<td class=\"n\" data-v=\"" + format("%.17g", v) + "\">" + text + "</td>";
}

constexpr const char* kStyle = R"(<style>
body { font: 14px system-ui, sans-serif; margin: 1.5em; color: #222; }
h1 { font-size: 1.3em; margin: 0 0 .3em; }
.totals { margin: .5em 0 1em; color: #444; }
table { border-collapse: collapse; }
th, td { padding: 4px 8px; border-bottom: 1px solid #ddd; vertical-align: middle; }
th { background: #f3f3f3; cursor: pointer; user-select: none; position: sticky; top: 0; }
th.sorted-asc::after { content: " \25B2"; } th.sorted-desc::after { content: " \25BC"; }
td.n { text-align: right; font-variant-numeric: tabular-nums; }
tr.failed td { background: #fff0f0; }
.note { color: #a00; font-size: .9em; max-width: 30em; }
img { display: block; }
</style>)";

// Sorting without a server or a library: a click on a header sorts by that column (numbers by data-v, text by its
// content), a second click reverses; `#sort=KEY` (a header's data-key, `-KEY` descending) sorts on load.
constexpr const char* kScript = R"(<script>
(function () {
  const table = document.getElementById('scans');
  const body = table.tBodies[0];
  const heads = Array.from(table.tHead.rows[0].cells);
  function sortBy(index, descending) {
    const rows = Array.from(body.rows);
    const key = r => { const c = r.cells[index]; return c.dataset.v !== undefined ? parseFloat(c.dataset.v) : c.textContent; };
    rows.sort((a, b) => { const x = key(a), y = key(b); const d = typeof x === 'number' ? x - y : String(x).localeCompare(String(y)); return descending ? -d : d; });
    rows.forEach(r => body.appendChild(r));
    heads.forEach((h, i) => { h.classList.remove('sorted-asc', 'sorted-desc'); if (i === index) h.classList.add(descending ? 'sorted-desc' : 'sorted-asc'); });
  }
  heads.forEach((h, i) => { if (h.dataset.key) h.addEventListener('click', () => sortBy(i, h.classList.contains('sorted-asc'))); });
  const m = /sort=(-?)([a-z_]+)/.exec(location.hash);
  if (m) { const i = heads.findIndex(h => h.dataset.key === m[2]); if (i >= 0) sortBy(i, m[1] === '-'); }
})();
</script>)";

}  // namespace

std::string summaryPathOf(const std::string& path) {
  std::error_code ec;
  if (fs::is_directory(path, ec)) return (fs::path(path) / "summary.json").string();
  return path;
}

Status writeHtmlReport(const std::string& summary_path, const std::string& html_path, const HtmlReportOptions& o,
                       std::shared_ptr<EmbreeDevice> device) {
  std::ifstream in(summary_path, std::ios::binary);
  if (!in) return makeError(ErrorCode::kIo, summary_path + ": cannot read the batch summary");
  json j;
  try {
    j = json::parse(in);
  } catch (const std::exception& e) {
    return makeError(ErrorCode::kMalformed, summary_path + ": not a batch summary (invalid JSON: " + e.what() + ")");
  }
  if (!j.is_object() || !j.contains("files") || !j["files"].is_array())
    return makeError(ErrorCode::kMalformed, summary_path + ": not a batch summary (no \"files\" array)");
  if (o.thumbnails && !device) {
    SP_ASSIGN_OR_RETURN(device, EmbreeDevice::create());
  }
  const fs::path summary_dir = fs::path(summary_path).parent_path();
  const fs::path html_dir = fs::absolute(fs::path(html_path)).parent_path();
  std::ostringstream h;
  const std::string job = j.value("job", std::string());
  h << "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">\n<title>scanpress: "
    << escape(job.empty() ? summary_path : job) << "</title>\n"
    << kStyle << "\n</head><body>\n<h1>scanpress batch: " << escape(job.empty() ? summary_path : job) << "</h1>\n";
  const json totals = j.value("totals", json::object());
  const size_t n_files = j["files"].size();
  h << "<div class=\"totals\">" << n_files << " file(s)";
  if (totals.is_object()) {
    const double in_b = totals.value("input_bytes", 0.0), out_b = totals.value("bytes", 0.0);
    if (out_b > 0)
      h << "; " << humanBytes(uint64_t(in_b)) << " in, " << humanBytes(uint64_t(out_b)) << " out, ratio "
        << format("%.2f", in_b / out_b);
    if (totals.contains("failed")) h << "; " << totals.value("failed", 0) << " failed";
  }
  h << "; exit code " << j.value("exit_code", 0) << "</div>\n";
  h << "<table id=\"scans\"><thead><tr><th>view</th><th data-key=\"file\">file</th><th data-key=\"status\">status</th>"
       "<th data-key=\"input_bytes\">input</th><th data-key=\"bytes\">output</th><th data-key=\"bpv\">bits/vertex</th>"
       "<th data-key=\"ratio\">ratio</th><th data-key=\"rms\">RMS error / diag</th>"
       "<th data-key=\"max\">max error / diag</th><th data-key=\"seconds\">time (s)</th>"
       "<th data-key=\"tiles\">tiles</th><th data-key=\"vertices\">vertices</th><th>error heat map</th></tr></thead>\n<tbody>\n";
  for (const json& f : j["files"]) {
    if (!f.is_object()) continue;
    const std::string input = f.value("input", std::string()), status = f.value("status", std::string("?"));
    const std::string output = locate(f.value("output", std::string()), summary_dir);
    std::string note = f.value("error", std::string()), image;
    if (o.thumbnails && !output.empty() && f.contains("bytes")) {
      std::string why;
      image = thumbnail(output, o, device, why);
      if (!why.empty()) note += (note.empty() ? "" : "; ") + why;
    }
    h << "<tr class=\"scan" << (status == "failed" ? " failed" : "") << "\"><td>";
    if (!image.empty())
      h << "<img class=\"thumb\" alt=\"" << escape(fs::path(input).filename().string()) << "\" width=\""
        << o.thumbnail_width << "\" height=\"" << o.thumbnail_height << "\" src=\"" << image << "\">";
    h << "</td><td>" << escape(input);
    if (!note.empty()) h << "<div class=\"note\">" << escape(note) << "</div>";
    h << "</td><td>" << escape(status) << "</td>";
    const bool counted = f.contains("bytes");
    auto num = [&](const char* key) { return f.value(key, 0.0); };
    if (counted) {
      h << cell(num("input_bytes"), humanBytes(uint64_t(num("input_bytes"))))
        << cell(num("bytes"), humanBytes(uint64_t(num("bytes")))) << cell(num("bpv"), format("%.2f", num("bpv")))
        << cell(num("ratio"), format("%.2f", num("ratio")));
    } else {
      h << cell(-1, "-") << cell(-1, "-") << cell(-1, "-") << cell(-1, "-");
    }
    if (f.contains("error_rms_relative")) {
      h << cell(num("error_rms_relative"), format("%.3e", num("error_rms_relative")))
        << cell(num("error_max_relative"), format("%.3e", num("error_max_relative")));
    } else {
      h << cell(-1, "not measured") << cell(-1, "not measured");
    }
    h << cell(num("seconds"), format("%.2f", num("seconds")))
      << cell(num("tiles"), counted ? format("%.0f", num("tiles")) : "-")
      << cell(num("vertices"), counted ? format("%.0f", num("vertices")) : "-") << "<td>";
    const std::string picture = locate(f.value("picture", std::string()), summary_dir);
    if (!picture.empty()) {
      std::error_code ec;
      fs::path rel = fs::relative(fs::absolute(picture), html_dir, ec);
      if (ec || rel.empty()) rel = fs::absolute(picture);
      // A relative URL: every byte but the unreserved ones and '/' percent-encoded (file names hold anything).
      std::string url;
      for (unsigned char c : rel.generic_string())
        if (std::isalnum(c) || c == '-' || c == '.' || c == '_' || c == '~' || c == '/') url += static_cast<char>(c);
        else {
          static constexpr char kHex[] = "0123456789ABCDEF";
          url += '%';
          url += kHex[c >> 4];
          url += kHex[c & 15];
        }
      h << "<a href=\"" << escape(url) << "\"><img class=\"heat\" alt=\"error heat map\" width=\"160\" src=\""
        << escape(url) << "\"></a>";
    }
    h << "</td></tr>\n";
  }
  h << "</tbody></table>\n" << kScript << "\n</body></html>\n";
  const std::string text = h.str();
  return writeFileAtomically(html_path,
                             std::span<const uint8_t>(reinterpret_cast<const uint8_t*>(text.data()), text.size()));
}

}  // namespace scanpress
