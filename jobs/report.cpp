#include "jobs/report.h"

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <set>
#include <sstream>

#include "jobs/batch.h"
#include "jobs/commands.h"
#include "jobs/shard.h"

namespace scanpress {
namespace {

using nlohmann::json;

// One level of a tile: its number, the payload bytes it needs, and what it means.
json levelJson(const CodecLevel& lv) {
  json j = {{"level", lv.level}, {"bytes", lv.end_bytes}, {"complete", lv.complete}, {"meaning", describeLevel(lv)}};
  switch (lv.kind) {
    case LevelKind::kCells:
      j["kind"] = "cells";
      j["cell_size"] = uint64_t(1) << lv.cell_bits;  // grid cells per axis
      break;
    case LevelKind::kSimplified:
      j["kind"] = "simplified";
      j["vertices"] = lv.vertices;
      j["max_error"] = lv.max_error;  // grid cells
      break;
    case LevelKind::kRemeshed:
      j["kind"] = "remeshed";
      j["spacing"] = lv.spacing;  // grid cells
      break;
  }
  return j;
}

json gridJson(const Grid& g) {
  return {{"origin", {g.origin[0], g.origin[1], g.origin[2]}}, {"cell", g.cell}, {"bits", g.bits}};
}

json errorSide(const ErrorStats& e, double diagonal) {
  const double d = diagonal > 0 ? diagonal : 1.0;
  return {{"mean", e.mean},
          {"rms", e.rms},
          {"max", e.max},
          {"samples", e.samples},
          {"mean_relative", e.mean / d},
          {"rms_relative", e.rms / d},
          {"max_relative", e.max / d}};
}

json errorJson(const ErrorStats& f, const ErrorStats& b, double diagonal) {
  return {{"diagonal", diagonal},
          {"forward", errorSide(f, diagonal)},
          {"backward", errorSide(b, diagonal)},
          {"symmetric", errorSide(symmetricOf(f, b), diagonal)}};
}

// Two vertex counts describe one container: the distinct vertices encoded (the report's `vertices` and `bpv`)
// and the vertices summed over tiles, a border vertex once per tile that holds it (the container header's
// count, so `info`'s `vertices` and `bpv`, and the report's `tile_vertices`). Both documents say which is
// which.
const json kReportCounts = {
    {"vertices", "distinct vertices encoded: input vertices that kept triangles use"},
    {"tile_vertices", "vertices summed over tiles (a border vertex once per tile): info's vertices"},
    {"bpv", "8 * bytes / vertices"},
    {"bpv_tile_vertices", "8 * bytes / tile_vertices: info's bpv"}};
const json kInfoCounts = {
    {"vertices", "vertices summed over tiles (a border vertex once per tile): an encode report's tile_vertices"},
    {"bpv",
     "8 * bytes / vertices (summed over tiles): an encode report's bpv_tile_vertices; its bpv divides "
     "by the distinct vertices"}};

json layoutJson(const AttributeLayout& l) {
  json scalars = json::array();
  for (const ScalarChannel& c : l.scalars)
    scalars.push_back({{"name", c.name}, {"type", scalarTypeName(c.type)}, {"bits", c.bits}});
  const bool lossless_normals = !l.hasNormals() && losslessNormalsWord(l.scalars).has_value();
  return {{"normals", l.hasNormals() || lossless_normals},
          {"normal_bits", l.normal_bits},
          {"lossless_normals", lossless_normals},  // float32 channels nx, ny, nz (listed in scalars)
          {"color_channels", l.color_channels},
          {"color_bits", l.hasColors() ? l.color_bits : 0},
          {"scalars", std::move(scalars)}};
}

// The target, what the search chose and tried, and whether the target was met.
json targetJson(const TargetReport& t) {
  json j = {{"kind", targetKindName(t.target.kind)}, {"fixed_bits", t.target.fixed_bits}};
  switch (t.target.kind) {
    case TargetKind::kMaxError:
      j["max_error"] = t.target.max_error;  // relative to the diagonal
      j["error"] = errorMetricName(t.target.metric);
      if (t.error >= 0) j["achieved_error"] = t.error;
      if (t.tile_error > 0) j["tile_error"] = t.tile_error;  // absolute, each tile's bound
      break;
    case TargetKind::kMaxBytes: j["max_bytes"] = t.target.max_bytes; break;
    case TargetKind::kBitsPerVertex: j["bpv"] = t.target.bpv; break;
    case TargetKind::kNone: break;
  }
  j["bits"] = t.bits;
  if (t.knob_cells >= 0) j["knob_cells"] = t.knob_cells;
  j["met"] = t.met;
  if (!t.status.isOk()) j["failure"] = t.status.toString();
  json attempts = json::array();
  for (const TargetAttempt& a : t.attempts) {
    json e = {{"codec", a.codec}, {"bits", a.bits}, {"bytes", a.bytes}, {"vertices", a.vertices}, {"met", a.met}};
    if (a.knob_cells >= 0) e["knob_cells"] = a.knob_cells;
    if (a.error >= 0) e["error"] = a.error;
    if (!a.refused.empty()) e["refused"] = a.refused;
    attempts.push_back(std::move(e));
  }
  j["attempts"] = std::move(attempts);
  return j;
}

}  // namespace

nlohmann::json encodeReport(const EncodeSettings& settings, const EncodeResult& r, const std::string& fingerprint) {
  json j;
  j["complete"] = r.failed_tiles == 0 && (!r.target || r.target->met);
  if (!fingerprint.empty()) j["fingerprint"] = fingerprint;
  j["input"] = settings.input;
  j["output"] = settings.output;
  std::error_code ec;
  const uint64_t input_bytes = std::filesystem::file_size(settings.input, ec);
  j["input_bytes"] = ec ? 0 : input_bytes;
  j["ratio"] = !ec && r.bytes ? double(input_bytes) / r.bytes : 0.0;  // input file size / container size
  j["format"] = r.read.format_detail;
  j["codec"] = r.codec;
  j["stages"] = r.stages;
  j["grid"] = gridJson(r.grid);
  j["attributes"] = layoutJson(r.layout);
  j["material_library"] = r.read.materials.library;  // kept (OBJ mtllib; empty: none)
  j["material"] = r.read.materials.material;
  j["texture_file"] = r.read.materials.texture;  // kept (PLY comment TextureFile; empty: none)
  j["input_vertices"] = r.read.vertices;
  j["input_faces"] = r.read.triangles;
  j["input_polygons_triangulated"] = r.read.polygons;
  j["vertices"] = r.vertices;
  j["faces"] = r.faces;
  j["point_cloud"] = r.point_cloud;
  j["tile_vertices"] = r.tile_vertices;
  j["degenerate_triangles_dropped"] = r.quantize.degenerate_triangles;
  j["unreferenced_vertices_dropped"] = r.quantize.unreferenced_vertices;
  // What the input holds that the container does not keep: unsupported by scanpress (yet), or dropped because
  // the settings asked (--no-normals, --no-colors).
  json dropped = json::array();
  for (const auto& d : r.read.dropped)
    dropped.push_back({{"name", d.name}, {"count", d.count}, {"reason", "unsupported"}});
  for (const auto& d : r.dropped_on_request)
    dropped.push_back({{"name", d.name}, {"count", d.count}, {"reason", "requested"}});
  j["dropped"] = std::move(dropped);
  j["bytes"] = r.bytes;
  j["bpv"] = r.bitsPerVertex();
  j["bpv_tile_vertices"] = r.tile_vertices ? 8.0 * r.bytes / r.tile_vertices : 0.0;  // `info`'s bpv
  j["counts"] = kReportCounts;
  j["bits_per_triangle"] = r.faces ? 8.0 * r.bytes / r.faces : 0.0;
  j["threads"] = r.threads;
  j["memory_budget"] = settings.memory_budget;
  j["out_of_core"] = r.out_of_core;
  j["peak_rss"] = r.peak_rss;
  const double total = r.seconds.read + r.seconds.quantize + r.seconds.tile + r.seconds.encode + r.seconds.write;
  j["seconds"] = {{"read", r.seconds.read},     {"quantize", r.seconds.quantize}, {"tile", r.seconds.tile},
                  {"encode", r.seconds.encode}, {"write", r.seconds.write},       {"total", total}};
  j["mtri_per_second"] = total > 0 ? r.faces / total / 1e6 : 0.0;
  j["failed_tiles"] = r.failed_tiles;
  if (r.measured) {
    j["error"] = errorJson(statsOf(r.forward), statsOf(r.backward), r.diagonal);
    j["error"]["settings"] = {{"samples_per_triangle", settings.measure.samples_per_triangle},
                              {"samples", settings.measure.samples},
                              {"seed", settings.measure.seed},
                              {"stratified", settings.measure.stratified},
                              {"vertices", settings.measure.vertices}};
  }
  if (r.target) j["target"] = targetJson(*r.target);
  json tiles = json::array();
  for (const auto& t : r.tiles) {
    json e = {{"id", t.id},       {"vertices", t.vertices},
              {"faces", t.faces}, {"border_vertices", t.border_vertices},
              {"bytes", t.bytes}, {"status", t.status.isOk() ? "ok" : "failed"}};
    if (!t.status.isOk()) e["failure"] = t.status.toString();
    else if (r.measured) e["error"] = errorJson(t.forward, t.backward, r.diagonal);
    if (t.status.isOk() && r.target && r.target->target.kind == TargetKind::kMaxError)
      e["within_target"] = t.target_met;
    if (t.knob_cells >= 0) e["knob_cells"] = t.knob_cells, e["knob_trials"] = t.knob_trials;
    tiles.push_back(std::move(e));
  }
  j["tiles"] = std::move(tiles);
  return j;
}

std::string encodeReportJson(const EncodeSettings& settings, const EncodeResult& result,
                             const std::string& fingerprint) {
  return encodeReport(settings, result, fingerprint).dump(2) + "\n";
}

std::string measureJson(const MeasureResult& r) {
  json j = errorJson(r.forward, r.backward, r.diagonal);
  j["samples"] = r.forward.samples + r.backward.samples;
  return j.dump(2) + "\n";
}

namespace {

json summaryTotals(const json& files) {
  uint64_t ok = 0, skipped = 0, failed = 0, bytes = 0, vertices = 0, input_bytes = 0;
  double seconds = 0, worst_rms = -1, worst_max = -1;
  for (const auto& e : files) {
    const std::string status = e.value("status", "");
    ok += status == "ok";
    skipped += status == "skipped";
    failed += status == "failed";
    bytes += e.value("bytes", uint64_t(0));
    vertices += e.value("vertices", uint64_t(0));
    input_bytes += e.value("input_bytes", uint64_t(0));
    seconds += e.value("seconds", 0.0);
    worst_rms = std::max(worst_rms, e.value("error_rms_relative", -1.0));
    worst_max = std::max(worst_max, e.value("error_max_relative", -1.0));
  }
  json t = {{"files", files.size()},
            {"ok", ok},
            {"skipped", skipped},
            {"failed", failed},
            {"bytes", bytes},
            {"vertices", vertices},
            {"bpv", vertices ? 8.0 * bytes / vertices : 0.0},
            {"input_bytes", input_bytes},
            {"ratio", bytes ? double(input_bytes) / bytes : 0.0},
            {"seconds", seconds}};
  if (worst_rms >= 0) {  // the largest of the files' measured errors
    t["worst_error_rms_relative"] = worst_rms;
    t["worst_error_max_relative"] = worst_max;
  }
  return t;
}

}  // namespace

std::string batchSummaryJson(const std::string& config_path, const BatchResult& batch, const Shard* shard) {
  json j;
  j["job"] = config_path;
  if (shard) j["shard"] = {{"index", shard->index}, {"count", shard->count}};
  json files = json::array();
  for (const auto& f : batch.files) {
    json e = {{"input", f.input}, {"output", f.output}, {"seconds", f.seconds}};
    if (f.report_written) e["report"] = f.report;  // only a report that exists
    if (!f.picture.empty()) e["picture"] = f.picture;
    switch (f.state) {
      case FileOutcome::State::kOk: e["status"] = "ok"; break;
      case FileOutcome::State::kSkipped: e["status"] = "skipped"; break;
      case FileOutcome::State::kFailed: e["status"] = "failed"; break;
    }
    if (!f.error.isOk()) {
      e["error"] = f.error.toString();
      e["exit_code"] = exitCodeFor(f.error.code());
    }
    if (f.counts) {  // this run's result, or a skipped output's report: totals cover both
      const FileOutcome::Counts& c = *f.counts;
      e["vertices"] = c.vertices;
      e["faces"] = c.faces;
      e["bytes"] = c.bytes;
      e["bpv"] = c.vertices ? 8.0 * c.bytes / c.vertices : 0.0;
      e["input_bytes"] = c.input_bytes;
      e["ratio"] = c.bytes ? double(c.input_bytes) / c.bytes : 0.0;
      if (c.rms_relative >= 0) {
        e["error_rms_relative"] = c.rms_relative;
        e["error_max_relative"] = c.max_relative;
      }
      e["tiles"] = c.tiles;
      e["failed_tiles"] = c.failed_tiles;
    }
    files.push_back(std::move(e));
  }
  j["totals"] = summaryTotals(files);
  j["files"] = std::move(files);
  j["exit_code"] = batch.exitCode();
  return j.dump(2) + "\n";
}

Result<MergedSummary> mergeShardSummaries(const std::string& config_path, const std::vector<std::string>& shard_paths,
                                          const std::vector<std::string>& expected_inputs) {
  json files = json::array();
  int exit_code = 0;
  std::set<std::string> seen;
  for (size_t i = 0; i < shard_paths.size(); ++i) {
    const std::string& path = shard_paths[i];
    const std::string which = "shard " + std::to_string(i) + " of " + std::to_string(shard_paths.size());
    std::ifstream f(path, std::ios::binary);
    if (!f)
      return makeError(ErrorCode::kIo, path + ": no summary of " + which +
                                           ": its task did not finish (run it again "
                                           "with --shard " +
                                           std::to_string(i) + "/" + std::to_string(shard_paths.size()) + ")");
    json j;
    try {
      j = json::parse(f);
    } catch (const std::exception& e) {
      return makeError(ErrorCode::kMalformed, path + ": the summary of " + which + " is not valid JSON: " + e.what());
    }
    const json* shard = j.is_object() && j.contains("shard") ? &j["shard"] : nullptr;
    if (!shard || !shard->is_object() || shard->value("index", -1) != static_cast<int>(i) ||
        shard->value("count", -1) != static_cast<int>(shard_paths.size()) || !j.contains("files") ||
        !j["files"].is_array())
      return makeError(ErrorCode::kMalformed, path + ": not the summary of " + which);
    if (j.value("job", "") != config_path)
      return makeError(ErrorCode::kInvalidArgument, path + ": the summary of " + which +
                                                        " was written by another job (" + j.value("job", "") + ")");
    exit_code = std::max(exit_code, j.value("exit_code", 0));
    for (const auto& e : j["files"]) {
      if (!e.is_object() || !e.contains("input") || !e["input"].is_string())
        return makeError(ErrorCode::kMalformed, path + ": a file entry without an input");
      if (!seen.insert(e["input"].get<std::string>()).second)
        return makeError(ErrorCode::kMalformed, path + ": " + e["input"].get<std::string>() +
                                                    " is in two shard summaries (shards of different splits?)");
      files.push_back(e);
    }
  }
  std::sort(files.begin(), files.end(), [](const json& a, const json& b) {
    return a["input"].get<std::string>() < b["input"].get<std::string>();
  });
  MergedSummary m;
  for (const auto& in : expected_inputs)
    if (!seen.count(in)) m.missing.push_back(in);
  json j;
  j["job"] = config_path;
  j["shards"] = shard_paths.size();
  j["totals"] = summaryTotals(files);
  if (!m.missing.empty()) j["missing"] = m.missing;
  m.files = files.size();
  j["files"] = std::move(files);
  m.exit_code = m.missing.empty() ? exit_code : std::max(exit_code, 3);
  j["exit_code"] = m.exit_code;
  m.json = j.dump(2) + "\n";
  return m;
}

std::string containerInfoJson(const ContainerFile& file) {
  const ContainerHeader& h = file.header();
  json j;
  j["format_version"] = h.version;
  j["grid"] = gridJson(h.grid);
  j["attributes"] = layoutJson(h.layout);
  j["material_library"] = h.materials.library;
  j["material"] = h.materials.material;
  j["texture_file"] = h.materials.texture;
  j["vertices"] = h.vertices;
  j["faces"] = h.faces;
  j["bytes"] = file.size();
  j["bpv"] = h.vertices ? 8.0 * file.size() / h.vertices : 0.0;
  j["counts"] = kInfoCounts;
  if (h.partial()) j["subset"] = {{"index", h.subset_index}, {"count", h.subset_count}};
  json tiles = json::array();
  // Progressive tiles list their levels (payload bytes needed for each, and what the level means, as the codec
  // states it); the container-wide list sums the bytes over tiles (a tile whose first level is coarser counts its
  // first level's bytes, one whose last level is finer its last one's) when every tile is progressive.
  std::vector<std::vector<CodecLevel>> tile_levels;
  uint32_t last_level = 0;
  bool all_progressive = !file.tiles().empty();
  for (const auto& t : file.tiles()) {
    json e = {{"id", t.tile_id},        {"codec", codecName(t.codec)}, {"codec_version", t.codec_version},
              {"bytes", t.chunk_bytes}, {"offset", t.offset},          {"vertices", t.vertices},
              {"faces", t.faces}};
    if (t.vertices > 0) {
      e["bounds"] = {{t.lo[0], t.lo[1], t.lo[2]}, {t.hi[0], t.hi[1], t.hi[2]}};
      const auto w = tileWorldBounds(t, h.grid);
      e["world_bounds"] = {{w[0], w[1], w[2]}, {w[3], w[4], w[5]}};
    }
    auto levels = file.tileLevels(t);
    if (!levels.isOk()) {
      e["levels_error"] = levels.status().toString();
      all_progressive = false;
    } else if (levels->empty()) {
      e["single_rate"] = true;
      all_progressive = false;
    } else {
      json l = json::array();
      for (const auto& lv : *levels) l.push_back(levelJson(lv));
      e["levels"] = std::move(l);
      last_level = std::max(last_level, levels->back().level);
      tile_levels.push_back(std::move(levels).value());
    }
    tiles.push_back(std::move(e));
  }
  if (all_progressive) {
    std::vector<uint64_t> level_total(size_t(last_level) + 1, 0);
    for (const auto& levels : tile_levels) addLevelBytes(levels, level_total);
    json l = json::array();
    for (uint32_t lv = 0; lv < level_total.size(); ++lv) l.push_back({{"level", lv}, {"bytes", level_total[lv]}});
    j["levels"] = std::move(l);
  }
  j["tiles"] = std::move(tiles);
  return j.dump(2) + "\n";
}

std::string containerInfoText(const ContainerFile& file) {
  const ContainerHeader& h = file.header();
  std::ostringstream os;
  os.precision(10);
  os << file.path() << ": scanpress container v" << h.version << "\n";
  if (h.partial())
    os << "  partial:   part " << h.subset_index << " of " << h.subset_count
       << " (encode --subset): only the tiles t with t % " << h.subset_count << " == " << h.subset_index
       << "; scanpress merge joins the parts\n";
  os << "  grid:      " << h.grid.bits << " bits, cell " << h.grid.cell << ", origin (" << h.grid.origin[0] << ", "
     << h.grid.origin[1] << ", " << h.grid.origin[2] << ")\n"
     << "  vertices:  " << h.vertices << " (decoded, summed over tiles: a border vertex once per tile)\n"
     << "  faces:     " << h.faces << "\n"
     << "  bytes:     " << file.size() << " (" << (h.vertices ? 8.0 * file.size() / h.vertices : 0.0)
     << " bpv over the vertices above; an encode report's bpv divides by the distinct vertices)\n"
     << "  normals:   "
     << (h.layout.hasNormals()                   ? std::to_string(h.layout.normal_bits) + "-bit octahedral"
         : losslessNormalsWord(h.layout.scalars) ? std::string("lossless (float channels nx, ny, nz)")
                                                 : std::string("no"))
     << "\n"
     << "  colors:    "
     << (h.layout.hasColors() ? std::to_string(h.layout.color_channels) + " channels of " +
                                    std::to_string(h.layout.color_bits) + " bits"
                              : "no")
     << "\n"
     << "  scalars:   " <<
      [&] {
    std::string s;
    for (const ScalarChannel& c : h.layout.scalars)
      s += (s.empty() ? "" : ", ") + c.name + " (" + scalarTypeName(c.type) +
           (c.bits ? ", multiples of 2^-" + std::to_string(int(c.bits)) : std::string()) + ")";
    return s.empty() ? std::string("no") : s;
  }() << "\n";
  const MaterialNames& m = h.materials;
  if (!m.library.empty() || !m.material.empty())
    os << "  material:  " << (m.material.empty() ? std::string("(none)") : m.material)
       << (m.library.empty() ? std::string() : " from " + m.library) << "\n";
  if (!m.texture.empty()) os << "  texture:   " << m.texture << "\n";
  os << "  tiles:     " << h.tile_count << "\n";
  for (const auto& t : file.tiles()) {
    os << "    tile " << t.tile_id << ": " << codecName(t.codec) << " v" << t.codec_version << ", " << t.vertices
       << " vertices, " << t.faces << " faces, " << t.chunk_bytes << " bytes";
    if (t.vertices > 0) {
      const auto w = tileWorldBounds(t, h.grid);
      os << ", box " << w[0] << "," << w[1] << "," << w[2] << "," << w[3] << "," << w[4] << "," << w[5];
    }
    // Progressive tiles: their levels, first and last, with what they mean.
    auto levels = file.tileLevels(t);
    if (levels.isOk() && !levels->empty())
      os << ", levels " << levels->front().level << ".." << levels->back().level << " ("
         << describeLevel(levels->front()) << " .. " << describeLevel(levels->back()) << ")";
    os << "\n";
  }
  return os.str();
}

}  // namespace scanpress
