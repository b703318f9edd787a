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
//
// Texture coordinates (runTexcoords): the scan read with its wedges (a vertex per distinct coordinate of its
// corners), snapped to scanpress's multiples of 2^-bits; scanpress codes those, and Draco gets one position per
// distinct grid position (its connectivity over positions, a seam an attribute seam, as its own OBJ loader builds
// it) with a coordinate per wedge, at -qt of the same bits (over its own range: on [0, 1] coordinates, the same
// step). The geometry alone is the scan as in the file.
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
#include "engine/quantize.h"
#include "jobs/mesh_io/mesh_reader.h"
#include "jobs/mesh_io/texcoords.h"

namespace scanpress {
namespace {

struct Config {
  const char* name;
  int normal_bits;  // 0: none
  bool colors;
};

// Draco's decoding of `buffer` (nullptr on failure).
std::unique_ptr<draco::Mesh> dracoDecode(const draco::EncoderBuffer& buffer) {
  draco::DecoderBuffer in;
  in.Init(buffer.data(), buffer.size());
  draco::Decoder dec;
  auto r = dec.DecodeMeshFromBuffer(&in);
  if (!r.ok()) return nullptr;
  return std::move(r).value();
}

// The points of `q` by quantized position: Draco reorders points, so its decoded ones are matched by position.
std::multimap<Vec3u, uint32_t> pointsAt(const QuantizedMesh& q) {
  std::multimap<Vec3u, uint32_t> at;
  for (uint32_t i = 0; i < uint32_t(q.positions.size()); ++i) at.emplace(q.positions[i], i);
  return at;
}

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
    const auto decoded = dracoDecode(buffer);
    if (!decoded) return 0;
    const auto& out = *decoded;
    const std::multimap<Vec3u, uint32_t> at = pointsAt(q);
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

// Draco -cl 10 on the wedge mesh `q` (texture coordinates in `q.scalars`, channels `tc` of `layout`) at -qt
// `uv_bits` (0: the positions alone, one per distinct grid position); 0 on failure. `max_error`: the largest
// coordinate difference after Draco's round trip, matched by position and nearest coordinate.
size_t dracoTexcoordBytes(const QuantizedMesh& q, const Grid& grid, const AttributeLayout& layout,
                          const TexcoordChannels& tc, int bits, int uv_bits, double* max_error) {
  const uint32_t n = uint32_t(q.positions.size());
  const size_t stride = size_t(layout.scalarStride());
  std::map<Vec3u, uint32_t> position_index;
  std::vector<uint32_t> value_of(n);
  for (uint32_t i = 0; i < n; ++i)
    value_of[i] = position_index.emplace(q.positions[i], uint32_t(position_index.size())).first->second;
  const auto uv = [&](uint32_t i) {
    const uint32_t* w = q.scalars.data() + i * stride;
    return std::array<float, 2>{float(floatChannelValue(layout.scalars[tc.u], w + tc.u_word)),
                                float(floatChannelValue(layout.scalars[tc.v], w + tc.v_word))};
  };
  // Points: the wedges, or without coordinates the distinct positions.
  const auto point = [&](uint32_t i) { return uv_bits ? i : value_of[i]; };
  const uint32_t points = uv_bits ? n : uint32_t(position_index.size());
  draco::Mesh dm;
  dm.set_num_points(points);
  draco::GeometryAttribute ga;
  ga.Init(draco::GeometryAttribute::POSITION, nullptr, 3, draco::DT_FLOAT32, false, 12, 0);
  const int pos_att = dm.AddAttribute(ga, false, uint32_t(position_index.size()));
  int uv_att = -1;
  if (uv_bits) {
    ga.Init(draco::GeometryAttribute::TEX_COORD, nullptr, 2, draco::DT_FLOAT32, false, 8, 0);
    uv_att = dm.AddAttribute(ga, true, n);
  }
  dm.attribute(pos_att)->SetExplicitMapping(points);
  for (const auto& [p, v] : position_index) {
    const Vec3d c = grid.dequantize(p);
    const float f[3] = {float(c[0]), float(c[1]), float(c[2])};
    dm.attribute(pos_att)->SetAttributeValue(draco::AttributeValueIndex(v), f);
  }
  for (uint32_t i = 0; i < n; ++i) {
    dm.attribute(pos_att)->SetPointMapEntry(draco::PointIndex(point(i)), draco::AttributeValueIndex(value_of[i]));
    if (uv_att >= 0) dm.attribute(uv_att)->SetAttributeValue(draco::AttributeValueIndex(i), uv(i).data());
  }
  for (const auto& t : q.triangles)
    dm.AddFace({draco::PointIndex(point(t[0])), draco::PointIndex(point(t[1])), draco::PointIndex(point(t[2]))});
  draco::Encoder enc;
  enc.SetAttributeQuantization(draco::GeometryAttribute::POSITION, bits);
  if (uv_att >= 0) enc.SetAttributeQuantization(draco::GeometryAttribute::TEX_COORD, uv_bits);
  enc.SetSpeedOptions(0, 0);  // -cl 10
  enc.SetEncodingMethod(draco::MESH_EDGEBREAKER_ENCODING);
  draco::EncoderBuffer buffer;
  if (!enc.EncodeMeshToBuffer(dm, &buffer).ok()) return 0;
  if (max_error && uv_att >= 0) {
    const auto decoded = dracoDecode(buffer);
    if (!decoded) return 0;
    const auto& out = *decoded;
    const std::multimap<Vec3u, uint32_t> at = pointsAt(q);
    const draco::PointAttribute* pa = out.GetNamedAttribute(draco::GeometryAttribute::POSITION);
    const draco::PointAttribute* ta = out.GetNamedAttribute(draco::GeometryAttribute::TEX_COORD);
    if (!pa || !ta) return 0;
    double worst = 0;
    for (uint32_t i = 0; i < out.num_points(); ++i) {
      float p[3], t[2];
      pa->GetMappedValue(draco::PointIndex(i), p);
      ta->GetMappedValue(draco::PointIndex(i), t);
      const auto range = at.equal_range(grid.quantize({p[0], p[1], p[2]}));
      if (range.first == range.second) return 0;
      double best = 1e300;
      for (auto j = range.first; j != range.second; ++j) {
        const auto w = uv(j->second);
        best = std::min(best, std::max(std::fabs(double(t[0]) - w[0]), std::fabs(double(t[1]) - w[1])));
      }
      worst = std::max(worst, best);
    }
    *max_error = worst;
  }
  return buffer.size();
}

}  // namespace

void runTexcoords(const std::string& scan, const std::string& path, const Mesh& as_in_file, int bits,
                  std::vector<AttributeRow>& rows) {
  auto wedged = readMeshFile(path);  // the default options: wedges at seams
  if (!wedged.isOk()) return;
  const auto tc = findTexcoords(wedged->scalar_channels);
  if (!tc) return;
  const Grid grid = *makeGrid(boundingBox(as_in_file), bits);
  const QuantizedMesh bare = *quantizeMesh(as_in_file, grid, {}, nullptr);
  std::map<std::string, size_t> geometry;
  for (const char* codec : {"kdtree", "octree", "edgebreaker"}) {
    auto e = encodeMesh(*findCodec(codec), TileContext{bits, {}}, bare);
    geometry[std::string("scanpress ") + codec] = e.isOk() ? e->payload.size() : 0;
  }
  for (int uv_bits : {10, 12, 14}) {
    AttributeLayout layout;
    layout.scalars = {wedged->scalar_channels[tc->u], wedged->scalar_channels[tc->v]};
    for (ScalarChannel& c : layout.scalars) c.bits = uint8_t(uv_bits);
    auto q = quantizeMesh(*wedged, grid, layout, nullptr);
    if (!q.isOk()) {
      std::fprintf(stderr, "%s: %s\n", scan.c_str(), q.status().toString().c_str());
      return;
    }
    const auto base = [&](const std::string& codec) {
      AttributeRow r;
      r.scan = scan;
      r.bits = bits;
      r.config = "uv " + std::to_string(uv_bits);
      r.codec = codec;
      r.vertices = bare.positions.size();
      r.geometry_bytes = geometry[codec];
      return r;
    };
    const TexcoordChannels pair = *findTexcoords(layout.scalars);
    const size_t stride = size_t(layout.scalarStride());
    // Draco's geometry alone: the same points without their coordinates (one per distinct grid position). Its -qt
    // spreads 2^qt - 1 steps over the coordinates' range: qt is the nearest to a step of ours, 2^-uv_bits.
    geometry["draco -cl 10"] = dracoTexcoordBytes(*q, grid, layout, pair, bits, 0, nullptr);
    double lo = 1e300, hi = -1e300;
    for (size_t i = 0; i < q->positions.size(); ++i)
      for (const auto& [ch, word] : {std::pair{pair.u, pair.u_word}, std::pair{pair.v, pair.v_word}}) {
        const double x = floatChannelValue(layout.scalars[ch], q->scalars.data() + i * stride + word);
        lo = std::min(lo, x), hi = std::max(hi, x);
      }
    const int draco_qt =
        std::clamp(int(std::lround(std::log2(std::max(hi - lo, 0.0) * std::ldexp(1.0, uv_bits) + 1))), 1, 30);
    for (const char* name : {"kdtree", "octree", "edgebreaker"}) {
      const CodecInfo& codec = *findCodec(name);
      AttributeRow r = base(std::string("scanpress ") + name);
      const TileContext ctx{bits, layout};
      auto e = encodeMesh(codec, ctx, *q);
      if (!e.isOk()) {
        std::fprintf(stderr, "%s %s: %s\n", scan.c_str(), name, e.status().toString().c_str());
        continue;
      }
      r.bytes = e->payload.size();
      auto d = codec.decode(ctx, payloadVersion(codec, *e), e->payload, limitsOf(e->decoded));
      if (d.isOk()) {  // exact: the same (position, u, v) vertices
        const auto key = [&](const QuantizedMesh& m) {
          std::vector<std::pair<Vec3u, std::vector<uint32_t>>> v;
          for (size_t i = 0; i < m.positions.size(); ++i)
            v.emplace_back(m.positions[i], std::vector<uint32_t>(m.scalars.begin() + i * stride,
                                                                 m.scalars.begin() + (i + 1) * stride));
          std::sort(v.begin(), v.end());
          v.erase(std::unique(v.begin(), v.end()), v.end());
          return v;
        };
        r.exact = key(*d) == key(*q);
      }
      rows.push_back(r);
    }
    AttributeRow r = base("draco -cl 10");
    double error = 0;
    r.bytes = dracoTexcoordBytes(*q, grid, layout, pair, bits, draco_qt, &error);
    r.max_uv_error = error;
    r.uv_qt = draco_qt;
    rows.push_back(r);
  }
}

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
      auto d = codec.decode(ctx, payloadVersion(codec, *e), e->payload, limitsOf(e->decoded));
      if (d.isOk()) {  // exact: the same (position, normal code, color) vertices
        // pm before v5: one vertex per position, the first's attributes.
        const bool welds = !codec.keepsAttributes(payloadVersion(codec, *e));
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
    if (r.codec.rfind("draco", 0) == 0 && r.max_uv_error >= 0) {
      char b[96];
      std::snprintf(b, sizeof b, "-qt %d: max texture coordinate error %.2g", r.uv_qt, r.max_uv_error);
      check = b;
    } else if (r.codec.rfind("draco", 0) == 0) {
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
