// Welding decoded tiles back into one mesh.
//
// All tiles of a container use the scan's one global grid, so a vertex that lies on a border between tiles has
// the same integer coordinates (and attributes) in every tile that holds it. weldTiles concatenates tiles and
// merges vertices of different tiles that share the weld key. By default the key is position, normal and color:
// two different scan vertices at one quantized position with different attributes stay apart (their attributes
// survive). Tiles decoded at a coarse level carry attributes that differ along a seam (each tile's own
// representatives, or attributes it derived on its own): those weld by position alone, a welded vertex keeping its
// first tile's attributes (the caller derives them again where that tile has none of its own). Vertices that share a position
// inside one tile are left as the codec returned them: welding never changes what one tile decodes to.
#pragma once

#include <algorithm>
#include <span>

#include "engine/mesh.h"

namespace scanpress {

enum class WeldBy { kPositionAndAttributes, kPosition };

// A vertex's identity for welding: position and attributes (zero attributes when welding by position). `s`: the
// vertex's scalar values (`stride` words, in its tile), compared word for word: a key is valid while its tile's
// mesh lives (a caller that keeps keys longer points them at a copy of the values, as the streamed decode does).
struct WeldKey {
  Vec3u p;
  OctNormal n;
  Rgba8 c;
  const uint32_t* s = nullptr;
  size_t stride = 0;
  bool operator==(const WeldKey& o) const {
    return p == o.p && n == o.n && c == o.c && stride == o.stride && (stride == 0 || std::equal(s, s + stride, o.s));
  }
};

struct WeldKeyHash {
  size_t operator()(const WeldKey& k) const;
};

// The key of vertex `v` of `mesh`.
WeldKey weldKey(const QuantizedMesh& mesh, size_t v, WeldBy by);

// `owner` (when given): per vertex of the result, the index of the tile it comes from (its first).
QuantizedMesh weldTiles(std::span<const QuantizedMesh> tiles, WeldBy by = WeldBy::kPositionAndAttributes,
                        std::vector<uint32_t>* owner = nullptr);

}  // namespace scanpress
