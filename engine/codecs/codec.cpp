#include "engine/codecs/codec.h"

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <optional>
#include <string>

#include "engine/octahedral.h"

namespace scanpress {
namespace {

// Payload floors (FORMAT.md, "The index bounds the decoder"). They bound what an index may claim per payload byte,
// so that decoding costs memory in proportion to the file. store cannot code a vertex in fewer than 6 bits nor a
// face in fewer than 3 (a tile below, repeated points, widens its coordinate fields). The entropy coders go far
// lower on legitimate input (kdtree: 0.15 bit per point on a dense lattice, 0.49 bit per vertex with its faces on a
// dense plane; edgebreaker codes real scans at 6-11 bits per vertex with their faces at 12 grid bits), so their floors
// are set below what they reach, and a payload below them is padded (hierarchy.cpp). A 6-bit floor for them (which
// keeps every container under 1 MiB under 256 MiB of decode memory) would pad real scans coded at low bits by up to
// half: that bound needs bounded-memory decoding instead (issue 23).
// The slack is small because a tile costs only 92 bytes of chunk header and index entry: a larger one would let
// many small tiles claim more than the floor.
constexpr PayloadFloor kStoreFloor{6.0, 3.0, 8};
// Version 2 of kdtree, octree and edgebreaker predicts normals and colors (attributes.h): a well-predicted attribute
// costs a few thousandths of a bit, so their floors count none (version 1 payloads, raw, are admitted all the more).
constexpr PayloadFloor kHierarchyFloor{1.0 / 8, 1.0 / 16, 8, false};

// edgebreaker: every point codes three residual classes and every face a symbol, each at least the cost of a
// model's likeliest symbol (a width of 2^15 less one per other symbol); the slack covers the header and flush.
constexpr PayloadFloor kEdgebreakerFloor{8.0 / 2048, 8.0 / 65536, 1024, false};
// pm: its base mesh is coded by store, kdtree or octree, and every vertex split costs at least its split flag, a
// placement symbol and three residual buckets, each a few thousandths of a bit at the models' most skewed
// probabilities: half the hierarchy codecs' floor per vertex and face.
constexpr PayloadFloor kPmFloor{4.0 / 1024, 4.0 / (1024 * 64), 1024, false};

// prm: edgebreaker's coding, where a regular point codes one coordinate instead of three: the same floor.
constexpr std::array<CodecInfo, 6> kCodecs = {{
    {CodecId::kStore, "store", 1, kStoreFloor, &storeEncode, &storeDecode},
    {CodecId::kKdtree, "kdtree", 5, kHierarchyFloor, &kdtreeEncode, &kdtreeDecode, &kdtreeLevels, &kdtreeDecodeLevel,
     true, 3},
    {CodecId::kOctree, "octree", 4, kHierarchyFloor, &octreeEncode, &octreeDecode, &octreeLevels, &octreeDecodeLevel,
     true, 3},
    {CodecId::kPm, "pm", 5, kPmFloor, &pmEncode, &pmDecode, &pmLevels, &pmDecodeLevel, false, 3, true, 5},
    {CodecId::kEdgebreaker, "edgebreaker", 2, kEdgebreakerFloor, &edgebreakerEncode, &edgebreakerDecode},
    {CodecId::kPrm, "prm", 2, kEdgebreakerFloor, &prmEncode, &prmDecode},
}};

}  // namespace

std::span<const CodecInfo> allCodecs() { return kCodecs; }

const CodecInfo* findCodec(CodecId id) {
  for (const auto& c : kCodecs)
    if (c.id == id) return &c;
  return nullptr;
}

const CodecInfo* findCodec(std::string_view name) {
  for (const auto& c : kCodecs)
    if (c.name == name) return &c;
  return nullptr;
}

std::string codecNames() {
  std::string out;
  for (const auto& c : kCodecs) out += (out.empty() ? "" : ", ") + std::string(c.name);
  return out;
}

std::string codecName(CodecId id) {
  const CodecInfo* c = findCodec(id);
  return c ? std::string(c->name) : "unknown(" + std::to_string(static_cast<int>(id)) + ")";
}

std::string describeLevel(const CodecLevel& l) {
  std::string s;
  switch (l.kind) {
    case LevelKind::kCells: s = "cells of 2^" + std::to_string(l.cell_bits) + " grid cells"; break;
    case LevelKind::kSimplified:
      s = std::to_string(l.vertices) + " vertices within " + std::to_string(l.max_error) + " grid cells";
      break;
    case LevelKind::kRemeshed: s = "remeshed on a grid of " + std::to_string(l.spacing) + " grid cells"; break;
  }
  if (l.complete) s += " (complete)";
  return s;
}

void addLevelBytes(std::span<const CodecLevel> levels, std::vector<uint64_t>& total) {
  size_t i = 0;
  for (uint32_t l = 0; l < total.size(); ++l) {
    while (i + 1 < levels.size() && levels[i].level < l) ++i;
    total[l] += levels[i].end_bytes;
  }
}

namespace {
double needBits(const PayloadFloor& f, const AttributeLayout& layout, uint64_t vertices, uint64_t faces) {
  double scalar_bits = 0;
  for (const ScalarChannel& c : layout.scalars) scalar_bits += 8.0 * scalarTypeBytes(c.type);
  const double attribute_bits = f.raw_attributes ? 2.0 * layout.normal_bits + 8.0 * layout.color_channels + scalar_bits
                                                 : 0.0;
  return double(vertices) * (f.bits_per_vertex + attribute_bits) + double(faces) * f.bits_per_face;
}
}  // namespace

bool PayloadFloor::admits(const AttributeLayout& layout, uint64_t vertices, uint64_t faces,
                          uint64_t payload_bytes) const {
  const double need_bits = needBits(*this, layout, vertices, faces);
  return need_bits <= 8.0 * (double(payload_bytes) + double(slack_bytes));
}

uint64_t PayloadFloor::minPayloadBytes(const AttributeLayout& layout, uint64_t vertices, uint64_t faces) const {
  const double bytes = std::ceil(needBits(*this, layout, vertices, faces) / 8.0) - double(slack_bytes);
  uint64_t n = bytes > 0 ? static_cast<uint64_t>(bytes) : 0;
  while (!admits(layout, vertices, faces, n)) ++n;  // rounding of the double products
  return n;
}

Result<EncodedTile> encodeMesh(const CodecInfo& codec, const TileContext& ctx, const QuantizedMesh& mesh,
                               const CodecOptions& options) {
  return codec.encode(ctx, TileView{mesh, {}}, options);
}

DecodeLimits limitsOf(const TileSummary& s) { return DecodeLimits{s.vertices, s.faces}; }

Status checkLimits(std::string_view what, uint64_t vertices, uint64_t faces, const DecodeLimits& limits) {
  if (vertices > limits.vertices || faces > limits.faces)
    return makeError(ErrorCode::kMalformed, std::string(what) + ": claims " + std::to_string(vertices) +
                                                " vertices and " + std::to_string(faces) +
                                                " faces, the tile index allows " + std::to_string(limits.vertices) +
                                                " and " + std::to_string(limits.faces));
  return Status::ok();
}

TileSummary summarize(const QuantizedMesh& mesh) {
  TileSummary s;
  s.vertices = static_cast<uint32_t>(mesh.positions.size());
  s.faces = static_cast<uint32_t>(mesh.triangles.size());
  for (const auto& p : mesh.positions)
    for (int a = 0; a < 3; ++a) s.lo[a] = std::min(s.lo[a], p[a]), s.hi[a] = std::max(s.hi[a], p[a]);
  return s;
}

Vec3d triangleCross(const std::vector<Vec3u>& positions, const Triangle& t) {
  Vec3d e1, e2;
  for (int a = 0; a < 3; ++a) {
    e1[a] = double(positions[t[1]][a]) - positions[t[0]][a];
    e2[a] = double(positions[t[2]][a]) - positions[t[0]][a];
  }
  return {e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]};
}

Vec3f derivedFloatNormal(const Vec3d& a) {
  const double len = std::sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2]);
  if (!(len > 0) || !std::isfinite(len)) return {0, 0, 1};
  return {float(a[0] / len), float(a[1] / len), float(a[2] / len)};
}

void deriveAttributes(QuantizedMesh& m, const AttributeLayout& layout, std::span<const uint8_t> keep) {
  std::vector<OctNormal> old_normals;
  std::vector<Rgba8> old_colors;
  ScalarValues old_scalars;
  if (!keep.empty()) old_normals.swap(m.normals), old_colors.swap(m.colors), old_scalars.swap(m.scalars);
  m.normals.clear();
  m.colors.clear();
  m.scalars.clear();
  // Lossless normals (float channels nx, ny, nz) are derived as octahedral ones are, not left zero.
  const std::optional<size_t> float_normals = layout.hasNormals() ? std::nullopt : losslessNormalsWord(layout.scalars);
  std::vector<Vec3d> acc;
  if (layout.hasNormals() || float_normals) {
    acc.assign(m.positions.size(), Vec3d{0, 0, 0});
    for (const auto& t : m.triangles) {
      const Vec3d nrm = triangleCross(m.positions, t);
      for (uint32_t v : t)
        for (int a = 0; a < 3; ++a) acc[v][a] += nrm[a];
    }
  }
  if (layout.hasNormals()) {
    m.normals.reserve(acc.size());
    for (const auto& a : acc)
      m.normals.push_back(encodeOctahedral(Vec3f{float(a[0]), float(a[1]), float(a[2])}, layout.normal_bits));
  }
  if (layout.hasColors()) m.colors.assign(m.positions.size(), Rgba8{128, 128, 128, 255});
  const size_t stride = size_t(layout.scalarStride());
  m.scalars.assign(m.positions.size() * stride, 0);  // zero: 0 or +0.0 at every type
  if (float_normals)
    for (size_t v = 0; v < acc.size(); ++v) {
      const Vec3f n = derivedFloatNormal(acc[v]);
      for (size_t k = 0; k < 3; ++k) m.scalars[v * stride + *float_normals + k] = std::bit_cast<uint32_t>(n[k]);
    }
  for (size_t v = 0; v < keep.size() && v < m.positions.size(); ++v)
    if (keep[v]) {
      if (v < old_normals.size() && !m.normals.empty()) m.normals[v] = old_normals[v];
      if (v < old_colors.size() && !m.colors.empty()) m.colors[v] = old_colors[v];
      if ((v + 1) * stride <= old_scalars.size())
        std::copy_n(old_scalars.begin() + v * stride, stride, m.scalars.begin() + v * stride);
    }
}

Status validateTile(const TileContext& ctx, const QuantizedMesh& mesh) {
  const size_t n = mesh.positions.size();
  if (ctx.layout.hasNormals() != !mesh.normals.empty() || (!mesh.normals.empty() && mesh.normals.size() != n))
    return makeError(ErrorCode::kMalformed, "normal count does not match the vertex count");
  if (ctx.layout.hasColors() != !mesh.colors.empty() || (!mesh.colors.empty() && mesh.colors.size() != n))
    return makeError(ErrorCode::kMalformed, "color count does not match the vertex count");
  if (mesh.scalars.size() != n * size_t(ctx.layout.scalarStride()))
    return makeError(ErrorCode::kMalformed, "scalar values do not match the vertex count");
  const uint32_t max_coord = (1u << ctx.bits) - 1;
  for (size_t i = 0; i < n; ++i)
    for (uint32_t c : mesh.positions[i])
      if (c > max_coord)
        return makeError(ErrorCode::kMalformed, "vertex " + std::to_string(i) + " lies outside the grid");
  const uint32_t max_oct = ctx.layout.hasNormals() ? (1u << ctx.layout.normal_bits) - 1 : 0;
  for (const auto& e : mesh.normals)
    if (e[0] > max_oct || e[1] > max_oct) return makeError(ErrorCode::kMalformed, "normal outside its range");
  for (size_t t = 0; t < mesh.triangles.size(); ++t)
    for (uint32_t v : mesh.triangles[t])
      if (v >= n)
        return makeError(ErrorCode::kMalformed, "triangle " + std::to_string(t) + " indexes vertex " +
                                                    std::to_string(v) + " of " + std::to_string(n));
  return Status::ok();
}

}  // namespace scanpress
