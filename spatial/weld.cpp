#include "spatial/weld.h"

#include <cstring>
#include <unordered_map>

namespace scanpress {

size_t WeldKeyHash::operator()(const WeldKey& k) const {
  uint64_t a;
  uint32_t b;
  std::memcpy(&a, &k.n, 4);
  std::memcpy(&b, &k.c, 4);
  uint64_t h = k.p[0] * 0x9E3779B97F4A7C15ull;
  h ^= (h >> 29) ^ (k.p[1] * 0xC2B2AE3D27D4EB4Full);
  h ^= (h >> 31) ^ (k.p[2] * 0x165667B19E3779F9ull);
  h ^= (h >> 27) ^ ((a << 32 | b) * 0x27D4EB2F165667C5ull);
  for (size_t i = 0; i < k.stride; ++i) h = (h ^ k.s[i]) * 0x100000001B3ull;
  return static_cast<size_t>(h ^ (h >> 32));
}

WeldKey weldKey(const QuantizedMesh& mesh, size_t v, WeldBy by) {
  const bool attributes = by == WeldBy::kPositionAndAttributes;
  const size_t stride = attributes && !mesh.positions.empty() ? mesh.scalars.size() / mesh.positions.size() : 0;
  return WeldKey{mesh.positions[v], !attributes || mesh.normals.empty() ? OctNormal{0, 0} : mesh.normals[v],
                 !attributes || mesh.colors.empty() ? Rgba8{0, 0, 0, 0} : mesh.colors[v],
                 stride ? mesh.scalars.data() + v * stride : nullptr, stride};
}

QuantizedMesh weldTiles(std::span<const QuantizedMesh> tiles, WeldBy by, std::vector<uint32_t>* owner) {
  if (owner) owner->clear();
  if (tiles.size() == 1) {
    if (owner) owner->assign(tiles[0].positions.size(), 0);
    return tiles[0];
  }
  QuantizedMesh out;
  struct Owner {
    uint32_t index;
    uint32_t tile;
  };
  std::unordered_map<WeldKey, Owner, WeldKeyHash> first;
  std::vector<uint32_t> remap;
  size_t vertices = 0, triangles = 0;
  for (const QuantizedMesh& tile : tiles) vertices += tile.positions.size(), triangles += tile.triangles.size();
  first.reserve(vertices);
  out.positions.reserve(vertices);  // an upper bound: no doubling copies at the peak
  out.triangles.reserve(triangles);
  for (uint32_t t = 0; t < tiles.size(); ++t) {
    const QuantizedMesh& tile = tiles[t];
    remap.assign(tile.positions.size(), 0);
    for (size_t v = 0; v < tile.positions.size(); ++v) {
      const WeldKey key = weldKey(tile, v, by);
      const uint32_t next = static_cast<uint32_t>(out.positions.size());
      auto [it, inserted] = first.try_emplace(key, Owner{next, t});
      if (!inserted && it->second.tile != t) {
        remap[v] = it->second.index;
        continue;
      }
      remap[v] = next;
      out.positions.push_back(tile.positions[v]);
      if (owner) owner->push_back(t);
      if (!tile.normals.empty()) out.normals.push_back(tile.normals[v]);
      if (!tile.colors.empty()) out.colors.push_back(tile.colors[v]);
      if (const size_t stride = tile.scalars.size() / tile.positions.size())
        out.scalars.insert(out.scalars.end(), tile.scalars.begin() + ptrdiff_t(v * stride),
                           tile.scalars.begin() + ptrdiff_t((v + 1) * stride));
    }
    for (const Triangle& tri : tile.triangles) out.triangles.push_back({remap[tri[0]], remap[tri[1]], remap[tri[2]]});
  }
  return out;
}

}  // namespace scanpress
