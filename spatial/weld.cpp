#include "spatial/weld.h"

#include <cstring>
#include <unordered_map>

namespace scanpress {
namespace {

// A vertex's identity for welding: position and attributes.
struct Key {
  Vec3u p;
  OctNormal n;
  Rgba8 c;
  bool operator==(const Key& o) const { return p == o.p && n == o.n && c == o.c; }
};

struct KeyHash {
  size_t operator()(const Key& k) const {
    uint64_t a;
    uint32_t b;
    std::memcpy(&a, &k.n, 4);
    std::memcpy(&b, &k.c, 4);
    uint64_t h = k.p[0] * 0x9E3779B97F4A7C15ull;
    h ^= (h >> 29) ^ (k.p[1] * 0xC2B2AE3D27D4EB4Full);
    h ^= (h >> 31) ^ (k.p[2] * 0x165667B19E3779F9ull);
    h ^= (h >> 27) ^ ((a << 32 | b) * 0x27D4EB2F165667C5ull);
    return static_cast<size_t>(h ^ (h >> 32));
  }
};

}  // namespace

QuantizedMesh weldTiles(std::span<const QuantizedMesh> tiles, WeldBy by) {
  if (tiles.size() == 1) return tiles[0];
  QuantizedMesh out;
  struct Owner {
    uint32_t index;
    uint32_t tile;
  };
  std::unordered_map<Key, Owner, KeyHash> first;
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
      const bool attributes = by == WeldBy::kPositionAndAttributes;
      const Key key{tile.positions[v], !attributes || tile.normals.empty() ? OctNormal{0, 0} : tile.normals[v],
                    !attributes || tile.colors.empty() ? Rgba8{0, 0, 0, 0} : tile.colors[v]};
      const uint32_t next = static_cast<uint32_t>(out.positions.size());
      auto [it, inserted] = first.try_emplace(key, Owner{next, t});
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
