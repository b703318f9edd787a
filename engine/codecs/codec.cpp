#include "engine/codecs/codec.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <string>

#include "engine/octahedral.h"

namespace scanpress {
namespace {

// Payload floors (FORMAT.md, "The index bounds the decoder"). They bound what an index may claim per payload byte,
// so that decoding a container of B bytes needs O(B) memory: no container under 1 MiB takes any command past
// 256 MiB (tests/test_limits.cpp, IndexLimits.Densest*: 217 MiB at most). At the peak of `decode` a kdtree point
// costs about 90 bytes and a plane vertex with its two faces about 270 (measured), so a vertex must cost 6 bits
// and a face 3.
// Codecs that compress below this (a dense lattice codes at 0.15 bit per point with kdtree, a dense plane at 0.5 bit
// per vertex with its faces) pad their payloads up to the floor. Normal and color bits are raw in every codec and
// come on top (PayloadFloor::admits).
// The slack is small because a tile costs only 92 bytes of chunk header and index entry: a larger one would let
// many small tiles claim more than the floor (with 1024 bytes of slack, 11,000 tiles of 1 MiB could claim 15M points).
constexpr PayloadFloor kStoreFloor{6.0, 3.0, 8};
constexpr PayloadFloor kHierarchyFloor{6.0, 3.0, 8};

constexpr std::array<CodecInfo, 3> kCodecs = {{
    {CodecId::kStore, "store", 1, kStoreFloor, &storeEncode, &storeDecode},
    {CodecId::kKdtree, "kdtree", 1, kHierarchyFloor, &kdtreeEncode, &kdtreeDecode, &kdtreeLevels, &kdtreeDecodeLevel},
    {CodecId::kOctree, "octree", 1, kHierarchyFloor, &octreeEncode, &octreeDecode, &octreeLevels, &octreeDecodeLevel},
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
  const double attribute_bits = 2.0 * layout.normal_bits + 8.0 * layout.color_channels;
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

void deriveAttributes(QuantizedMesh& m, const AttributeLayout& layout) {
  m.normals.clear();
  m.colors.clear();
  if (layout.hasNormals()) {
    std::vector<Vec3d> acc(m.positions.size(), Vec3d{0, 0, 0});
    for (const auto& t : m.triangles) {
      Vec3d e1, e2;
      for (int a = 0; a < 3; ++a) {
        e1[a] = double(m.positions[t[1]][a]) - m.positions[t[0]][a];
        e2[a] = double(m.positions[t[2]][a]) - m.positions[t[0]][a];
      }
      const Vec3d nrm{e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]};
      for (uint32_t v : t)
        for (int a = 0; a < 3; ++a) acc[v][a] += nrm[a];
    }
    m.normals.reserve(acc.size());
    for (const auto& a : acc)
      m.normals.push_back(encodeOctahedral(Vec3f{float(a[0]), float(a[1]), float(a[2])}, layout.normal_bits));
  }
  if (layout.hasColors()) m.colors.assign(m.positions.size(), Rgba8{128, 128, 128, 255});
}

Status validateTile(const TileContext& ctx, const QuantizedMesh& mesh) {
  const size_t n = mesh.positions.size();
  if (ctx.layout.hasNormals() != !mesh.normals.empty() || (!mesh.normals.empty() && mesh.normals.size() != n))
    return makeError(ErrorCode::kMalformed, "normal count does not match the vertex count");
  if (ctx.layout.hasColors() != !mesh.colors.empty() || (!mesh.colors.empty() && mesh.colors.size() != n))
    return makeError(ErrorCode::kMalformed, "color count does not match the vertex count");
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
