#include "engine/codecs/codec.h"

#include <array>
#include <string>

namespace scanpress {
namespace {

constexpr std::array<CodecInfo, 3> kCodecs = {{
    {CodecId::kStore, "store", 1, &storeEncode, &storeDecode},
    {CodecId::kKdtree, "kdtree", 1, &kdtreeEncode, &kdtreeDecode, &kdtreeLevels, &kdtreeDecodeLevel,
     &hierarchyPayloadVertices},
    {CodecId::kOctree, "octree", 1, &octreeEncode, &octreeDecode, &octreeLevels, &octreeDecodeLevel,
     &hierarchyPayloadVertices},
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

void addLevelBytes(std::span<const CodecLevel> levels, std::vector<uint64_t>& total) {
  size_t i = 0;
  for (uint32_t l = 0; l < total.size(); ++l) {
    while (i + 1 < levels.size() && levels[i].level < l) ++i;
    total[l] += levels[i].end_bytes;
  }
}

uint64_t decodedVertexCount(const CodecInfo& codec, const QuantizedMesh& mesh, std::span<const uint8_t> payload) {
  return codec.payload_vertices ? codec.payload_vertices(payload) : mesh.positions.size();
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
