#include "spatial/weld.h"

#include <unordered_map>

namespace scanpress {
namespace {

struct PositionHash {
  size_t operator()(const Vec3u& p) const {
    uint64_t h = p[0] * 0x9E3779B97F4A7C15ull;
    h ^= (h >> 29) ^ (p[1] * 0xC2B2AE3D27D4EB4Full);
    h ^= (h >> 31) ^ (p[2] * 0x165667B19E3779F9ull);
    return static_cast<size_t>(h ^ (h >> 32));
  }
};

}  // namespace

QuantizedMesh weldTiles(std::span<const QuantizedMesh> tiles) {
  QuantizedMesh out;
  if (tiles.size() == 1) return tiles[0];
  struct Owner {
    uint32_t index;
    uint32_t tile;
  };
  std::unordered_map<Vec3u, Owner, PositionHash> first;
  std::vector<uint32_t> remap;
  for (uint32_t t = 0; t < tiles.size(); ++t) {
    const QuantizedMesh& tile = tiles[t];
    remap.assign(tile.positions.size(), 0);
    for (size_t v = 0; v < tile.positions.size(); ++v) {
      const uint32_t next = static_cast<uint32_t>(out.positions.size());
      auto [it, inserted] = first.try_emplace(tile.positions[v], Owner{next, t});
      if (!inserted && it->second.tile != t) {
        remap[v] = it->second.index;
        continue;
      }
      remap[v] = next;
      out.positions.push_back(tile.positions[v]);
      if (!tile.normals.empty()) out.normals.push_back(tile.normals[v]);
      if (!tile.colors.empty()) out.colors.push_back(tile.colors[v]);
    }
    for (const Triangle& tri : tile.triangles) out.triangles.push_back({remap[tri[0]], remap[tri[1]], remap[tri[2]]});
  }
  return out;
}

}  // namespace scanpress
