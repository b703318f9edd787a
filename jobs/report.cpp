#include "jobs/report.h"

#include <nlohmann/json.hpp>

#include <sstream>

namespace scanpress {
namespace {

using nlohmann::json;

std::string codecName(CodecId id) {
  const CodecInfo* c = findCodec(id);
  return c ? std::string(c->name) : "unknown(" + std::to_string(static_cast<int>(id)) + ")";
}

json gridJson(const Grid& g) {
  return {{"origin", {g.origin[0], g.origin[1], g.origin[2]}}, {"cell", g.cell}, {"bits", g.bits}};
}

json layoutJson(const AttributeLayout& l) {
  return {{"normals", l.hasNormals()}, {"normal_bits", l.normal_bits}, {"color_channels", l.color_channels}};
}

}  // namespace

nlohmann::json encodeReport(const EncodeSettings& settings, const EncodeResult& r) {
  json j;
  j["input"] = settings.input;
  j["output"] = settings.output;
  j["format"] = r.read.format_detail;
  j["codec"] = r.codec;
  j["grid"] = gridJson(r.grid);
  j["attributes"] = layoutJson(r.layout);
  j["input_vertices"] = r.read.vertices;
  j["input_faces"] = r.read.triangles;
  j["input_polygons_triangulated"] = r.read.polygons;
  j["vertices"] = r.vertices;
  j["faces"] = r.faces;
  j["tile_vertices"] = r.tile_vertices;
  j["degenerate_triangles_dropped"] = r.quantize.degenerate_triangles;
  j["unreferenced_vertices_dropped"] = r.quantize.unreferenced_vertices;
  j["bytes"] = r.bytes;
  j["bpv"] = r.bitsPerVertex();
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
  json tiles = json::array();
  for (const auto& t : r.tiles) {
    json e = {{"id", t.id},   {"vertices", t.vertices}, {"faces", t.faces}, {"border_vertices", t.border_vertices},
              {"bytes", t.bytes}, {"status", t.status.isOk() ? "ok" : "failed"}};
    if (!t.status.isOk()) e["error"] = t.status.toString();
    tiles.push_back(std::move(e));
  }
  j["tiles"] = std::move(tiles);
  return j;
}

std::string encodeReportJson(const EncodeSettings& settings, const EncodeResult& result) {
  return encodeReport(settings, result).dump(2) + "\n";
}

std::string containerInfoJson(const ContainerFile& file) {
  const ContainerHeader& h = file.header();
  json j;
  j["format_version"] = h.version;
  j["grid"] = gridJson(h.grid);
  j["attributes"] = layoutJson(h.layout);
  j["vertices"] = h.vertices;
  j["faces"] = h.faces;
  j["bytes"] = file.size();
  j["bpv"] = h.vertices ? 8.0 * file.size() / h.vertices : 0.0;
  json tiles = json::array();
  for (const auto& t : file.tiles()) {
    json e = {{"id", t.tile_id},
              {"codec", codecName(t.codec)},
              {"codec_version", t.codec_version},
              {"bytes", t.chunk_bytes},
              {"offset", t.offset},
              {"vertices", t.vertices},
              {"faces", t.faces}};
    if (t.vertices > 0) e["bounds"] = {{t.lo[0], t.lo[1], t.lo[2]}, {t.hi[0], t.hi[1], t.hi[2]}};
    tiles.push_back(std::move(e));
  }
  j["tiles"] = std::move(tiles);
  return j.dump(2) + "\n";
}

std::string containerInfoText(const ContainerFile& file) {
  const ContainerHeader& h = file.header();
  std::ostringstream os;
  os.precision(10);
  os << file.path() << ": scanpress container v" << h.version << "\n"
     << "  grid:      " << h.grid.bits << " bits, cell " << h.grid.cell << ", origin (" << h.grid.origin[0] << ", "
     << h.grid.origin[1] << ", " << h.grid.origin[2] << ")\n"
     << "  vertices:  " << h.vertices << "\n"
     << "  faces:     " << h.faces << "\n"
     << "  bytes:     " << file.size() << " (" << (h.vertices ? 8.0 * file.size() / h.vertices : 0.0) << " bpv)\n"
     << "  normals:   " << (h.layout.hasNormals() ? std::to_string(h.layout.normal_bits) + "-bit octahedral" : "no")
     << "\n"
     << "  colors:    " << (h.layout.hasColors() ? std::to_string(h.layout.color_channels) + " channels" : "no")
     << "\n"
     << "  tiles:     " << h.tile_count << "\n";
  for (const auto& t : file.tiles())
    os << "    tile " << t.tile_id << ": " << codecName(t.codec) << " v" << t.codec_version << ", " << t.vertices
       << " vertices, " << t.faces << " faces, " << t.chunk_bytes << " bytes\n";
  return os.str();
}

}  // namespace scanpress
