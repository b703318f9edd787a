// scanpress-compare's attribute comparison (issue 22): on scans with normals or colors, the bytes that attributes
// add to a file, for scanpress's lossless codecs (pm lossless among them) and for Draco -cl 10, at the same
// precisions.
//
// Both coders get the same values: the scan's normals quantized to scanpress's octahedral codes (then given to
// Draco as the unit vectors those codes name, with -qn at the same bits) and its 8-bit colors (Draco does not
// quantize integer attributes). A configuration's attribute bytes are the file's bytes minus those of the same
// coder on the positions and triangles alone. scanpress must give back its codes exactly (pm: per position, those of
// the scan's first vertex there, as its weld keeps them); for Draco the table shows
// the largest angle between its decoded normals and the input's (its octahedral grid is not ours).
#include <draco/compression/decode.h>
#include <draco/compression/encode.h>
#include <draco/mesh/mesh.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>

#include "bench/compare.h"
#include "engine/codecs/codec.h"
#include "engine/octahedral.h"

namespace scanpress {
namespace {

struct Config {
  const char* name;
  int normal_bits;  // 0: none
  bool colors;
};

size_t dracoBytes(const QuantizedMesh& q, const Grid& grid, const AttributeLayout& layout, int bits,
                  double* max_angle_deg, bool* colors_exact) {
  draco::Mesh dm;
  const uint32_t n = uint32_t(q.positions.size());
  dm.set_num_points(n);
  draco::GeometryAttribute ga;
  ga.Init(draco::GeometryAttribute::POSITION, nullptr, 3, draco::DT_FLOAT32, false, 12, 0);
  const int pos_att = dm.AddAttribute(ga, true, n);
  int normal_att = -1, color_att = -1;
  if (layout.hasNormals()) {
    ga.Init(draco::GeometryAttribute::NORMAL, nullptr, 3, draco::DT_FLOAT32, false, 12, 0);
    normal_att = dm.AddAttribute(ga, true, n);
  }
  if (layout.hasColors()) {
    ga.Init(draco::GeometryAttribute::COLOR, nullptr, layout.color_channels, draco::DT_UINT8, true,
            layout.color_channels, 0);
    color_att = dm.AddAttribute(ga, true, n);
  }
  for (uint32_t i = 0; i < n; ++i) {
    const Vec3d c = grid.dequantize(q.positions[i]);
    const float f[3] = {float(c[0]), float(c[1]), float(c[2])};
    dm.attribute(pos_att)->SetAttributeValue(draco::AttributeValueIndex(i), f);
    if (normal_att >= 0) {
      const Vec3f d = decodeOctahedral(q.normals[i], layout.normal_bits);
      dm.attribute(normal_att)->SetAttributeValue(draco::AttributeValueIndex(i), d.data());
    }
    if (color_att >= 0) dm.attribute(color_att)->SetAttributeValue(draco::AttributeValueIndex(i), q.colors[i].data());
  }
  for (const auto& t : q.triangles)
    dm.AddFace({draco::PointIndex(t[0]), draco::PointIndex(t[1]), draco::PointIndex(t[2])});
  draco::Encoder enc;
  enc.SetAttributeQuantization(draco::GeometryAttribute::POSITION, bits);
  if (layout.hasNormals()) enc.SetAttributeQuantization(draco::GeometryAttribute::NORMAL, layout.normal_bits);
  enc.SetSpeedOptions(0, 0);  // -cl 10
  enc.SetEncodingMethod(draco::MESH_EDGEBREAKER_ENCODING);
  draco::EncoderBuffer buffer;
  if (!enc.EncodeMeshToBuffer(dm, &buffer).ok()) return 0;
  if (max_angle_deg || colors_exact) {
    draco::DecoderBuffer in;
    in.Init(buffer.data(), buffer.size());
    draco::Decoder dec;
    auto r = dec.DecodeMeshFromBuffer(&in);
    if (!r.ok()) return 0;
    const auto& out = *r.value();
    // Draco reorders points: match them to the input by quantized position (first unused input point there).
    std::multimap<Vec3u, uint32_t> at;
    for (uint32_t i = 0; i < n; ++i) at.emplace(q.positions[i], i);
    const draco::PointAttribute* pa = out.GetNamedAttribute(draco::GeometryAttribute::POSITION);
    const draco::PointAttribute* na = out.GetNamedAttribute(draco::GeometryAttribute::NORMAL);
    const draco::PointAttribute* ca = out.GetNamedAttribute(draco::GeometryAttribute::COLOR);
    double worst = 0;
    bool exact = true;
    for (uint32_t i = 0; i < out.num_points(); ++i) {
      float p[3];
      pa->GetMappedValue(draco::PointIndex(i), p);
      auto it = at.find(grid.quantize({p[0], p[1], p[2]}));
      if (it == at.end()) return 0;
      if (na) {  // several input points at one position: the closest normal among them
        double best = 180;
        float d[3];
        na->GetMappedValue(draco::PointIndex(i), d);
        for (auto j = at.equal_range(it->first).first; j != at.equal_range(it->first).second; ++j) {
          const Vec3f w = decodeOctahedral(q.normals[j->second], layout.normal_bits);
          const double dot = std::clamp(double(d[0]) * w[0] + double(d[1]) * w[1] + double(d[2]) * w[2], -1.0, 1.0);
          best = std::min(best, std::acos(dot) * 180 / M_PI);
        }
        worst = std::max(worst, best);
      }
      if (ca) {
        uint8_t c[4] = {0, 0, 0, 255};
        ca->GetMappedValue(draco::PointIndex(i), c);
        bool any = false;
        for (auto j = at.equal_range(it->first).first; j != at.equal_range(it->first).second; ++j)
          any |= std::equal(c, c + layout.color_channels, q.colors[j->second].begin());
        exact &= any;
      }
    }
    if (max_angle_deg) *max_angle_deg = worst;
    if (colors_exact) *colors_exact = exact;
  }
  return buffer.size();
}

}  // namespace

void runAttributes(const std::string& scan, const Mesh& mesh, int bits, std::vector<AttributeRow>& rows) {
  const bool has_normals = !mesh.normals.empty(), has_colors = !mesh.colors.empty();
  if (!has_normals && !has_colors) return;
  const Grid grid = *makeGrid(boundingBox(mesh), bits);
  std::vector<Config> configs;
  if (has_normals) configs.push_back({"normals 10", 10, false}), configs.push_back({"normals 12", 12, false});
  if (has_colors) configs.push_back({"colors 8", 0, true});
  if (has_normals && has_colors) configs.push_back({"all (normals 12)", 12, true});
  const QuantizedMesh bare = *quantizeMesh(mesh, grid, {}, nullptr);
  std::map<std::string, size_t> geometry;  // per coder
  for (const char* codec : {"kdtree", "octree", "edgebreaker", "pm"}) {
    auto e = encodeMesh(*findCodec(codec), TileContext{bits, {}}, bare);
    geometry[std::string("scanpress ") + codec] = e.isOk() ? e->payload.size() : 0;
  }
  geometry["draco -cl 10"] = dracoBytes(bare, grid, {}, bits, nullptr, nullptr);
  for (const Config& cfg : configs) {
    const AttributeLayout layout{uint8_t(cfg.normal_bits), uint8_t(cfg.colors ? mesh.color_channels : 0)};
    const QuantizedMesh q = *quantizeMesh(mesh, grid, layout, nullptr);
    auto base = [&](const std::string& codec) {
      AttributeRow r;
      r.scan = scan;
      r.bits = bits;
      r.config = cfg.name;
      r.codec = codec;
      r.vertices = q.positions.size();
      r.geometry_bytes = geometry[codec];
      return r;
    };
    for (const char* name : {"kdtree", "octree", "edgebreaker", "pm"}) {
      const CodecInfo& codec = *findCodec(name);
      AttributeRow r = base(std::string("scanpress ") + name);
      const TileContext ctx{bits, layout};
      auto e = encodeMesh(codec, ctx, q);
      if (!e.isOk()) {
        std::fprintf(stderr, "%s %s: %s\n", scan.c_str(), name, e.status().toString().c_str());
        continue;
      }
      r.bytes = e->payload.size();
      auto d = codec.decode(ctx, codec.version, e->payload, limitsOf(e->decoded));
      if (d.isOk()) {                                // exact: the same (position, normal code, color) vertices
        const bool welds = !codec.keeps_attributes;  // pm: one vertex per position, the first's attributes
        auto key = [&](const QuantizedMesh& m) {
          std::vector<std::tuple<Vec3u, OctNormal, Rgba8>> v;
          for (size_t i = 0; i < m.positions.size(); ++i)
            v.emplace_back(m.positions[i], m.normals.empty() ? OctNormal{} : m.normals[i],
                           m.colors.empty() ? Rgba8{} : m.colors[i]);
          if (welds) {
            std::stable_sort(v.begin(), v.end(),
                             [](const auto& a, const auto& b) { return std::get<0>(a) < std::get<0>(b); });
            v.erase(std::unique(v.begin(), v.end(),
                                [](const auto& a, const auto& b) { return std::get<0>(a) == std::get<0>(b); }),
                    v.end());
          }
          std::sort(v.begin(), v.end());
          v.erase(std::unique(v.begin(), v.end()), v.end());
          return v;
        };
        r.exact = key(*d) == key(q);
        r.max_angle_deg = r.exact ? 0 : -1;
      }
      rows.push_back(r);
    }
    AttributeRow r = base("draco -cl 10");
    double angle = 0;
    bool colors_exact = true;
    r.bytes = dracoBytes(q, grid, layout, bits, layout.hasNormals() ? &angle : nullptr, &colors_exact);
    r.exact = false;
    r.max_angle_deg = layout.hasNormals() ? angle : 0;
    r.colors_exact = colors_exact;
    rows.push_back(r);
  }
}

void writeAttributeTable(std::ostream& md, const std::vector<AttributeRow>& rows) {
  if (rows.empty()) return;
  md << "\n## Attributes\n\n| scan | bits | attributes | coder | file bytes | attribute bytes | attribute bits per "
        "vertex | exact (scanpress) / max normal angle, colors exact (Draco) |\n|---|---:|---|---|---:|---:|---:|---|\n";
  char line[512];
  for (const auto& r : rows) {
    const long long attr = (long long)r.bytes - (long long)r.geometry_bytes;
    std::string check;
    if (r.codec.rfind("draco", 0) == 0) {
      char b[96];
      std::snprintf(b, sizeof b, "%.3f deg, colors %s", r.max_angle_deg, r.colors_exact ? "exact" : "NOT exact");
      check = b;
    } else {
      check = r.exact ? "exact" : "NOT EXACT";
    }
    std::snprintf(line, sizeof line, "| %s | %d | %s | %s | %llu | %lld | %.2f | %s |\n", r.scan.c_str(), r.bits,
                  r.config.c_str(), r.codec.c_str(), (unsigned long long)r.bytes, attr,
                  8.0 * double(attr) / double(r.vertices), check.c_str());
    md << line;
  }
  // Per configuration and bits: scanpress's attribute bytes and file bytes over Draco's, median over the scans.
  md << "\n| attributes | bits | coder | median attribute bytes / Draco's | median file bytes / Draco's | scans "
        "|\n|---|---:|---|---:|---:|---:|\n";
  std::map<std::tuple<std::string, int, std::string>, std::pair<std::vector<double>, std::vector<double>>> ratios;
  for (const auto& r : rows) {
    if (r.codec.rfind("draco", 0) == 0) continue;
    for (const auto& d : rows)
      if (d.scan == r.scan && d.bits == r.bits && d.config == r.config && d.codec.rfind("draco", 0) == 0) {
        const double a = double(r.bytes) - double(r.geometry_bytes), b = double(d.bytes) - double(d.geometry_bytes);
        auto& [attr, file] = ratios[{r.config, r.bits, r.codec}];
        attr.push_back(b > 0 ? a / b : 0);
        file.push_back(d.bytes ? double(r.bytes) / double(d.bytes) : 0);
      }
  }
  auto median = [](std::vector<double> v) {
    std::sort(v.begin(), v.end());
    return v.empty() ? 0.0 : v.size() % 2 ? v[v.size() / 2] : 0.5 * (v[v.size() / 2 - 1] + v[v.size() / 2]);
  };
  for (const auto& [key, v] : ratios) {
    std::snprintf(line, sizeof line, "| %s | %d | %s | %.3f | %.3f | %zu |\n", std::get<0>(key).c_str(),
                  std::get<1>(key), std::get<2>(key).c_str(), median(v.first), median(v.second), v.first.size());
    md << line;
  }
}

}  // namespace scanpress
