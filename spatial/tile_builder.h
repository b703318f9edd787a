// Building one tile's local mesh, with its lock flags, from the scan's tiled triangles.
//
// The tiler (spatial/tiling.h) assigns each triangle to the tile holding its centroid; the caller keeps the
// triangles of each tile (jobs/scan_store.h: in memory or in scratch files) and the scan's vertex records. For one
// tile, buildTileMesh gives the TileMesh a tile task works on (engine/tile.h): local vertex ids in order of first
// use, the records read in global-id order (runs of nearby ids become one read when the records are on disk), and
// each vertex's border flag, which is its lock flag for the tile's stages: a vertex is on the border when some
// triangle of another tile uses it, that is when the tile's triangles use it fewer times than the scan's do.
//
// Thread safety: buildTileMesh may run for many tiles at once if VertexSource::read may.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "engine/mesh.h"
#include "engine/status.h"
#include "engine/tile.h"
#include "spatial/tiling.h"

namespace scanpress {

// One vertex of a scan as the tiler keeps it.
struct VertexRecord {
  Vec3u q{0, 0, 0};
  uint32_t valence = 0;  // triangles (kept after quantization) that use the vertex, in the whole scan
  OctNormal normal{0, 0};
  Rgba8 color{255, 255, 255, 255};
  Vec3f original{0, 0, 0};  // input position relative to the grid origin (for measuring the error)
};
static_assert(sizeof(VertexRecord) == 36);

// Where vertex records are read from.
class VertexSource {
 public:
  virtual ~VertexSource() = default;
  // Records for sorted, unique global ids, in that order.
  virtual Status read(std::span<const uint32_t> sorted_ids, std::vector<VertexRecord>& out) const = 0;
  // Their scalar values (the layout's scalarStride() words each), in that order.
  virtual Status readScalars(std::span<const uint32_t> sorted_ids, size_t stride, ScalarValues& out) const = 0;
};

// A triangle (global vertex ids) with its centroid on the grid, between quantization and binning.
struct SpilledTriangle {
  Triangle t;
  Vec3u centroid;
};

// The tile of a triangle; kInternal if its centroid lies in no tile (the index was built from these centroids).
inline Result<uint32_t> tileOfTriangle(const TileIndex& index, const SpilledTriangle& t) {
  const uint32_t tile = index.tileOf(t.centroid);
  if (tile == UINT32_MAX) return makeError(ErrorCode::kInternal, "triangle centroid outside every tile");
  return tile;
}

// Builds tile `tile` from its triangles over global ids. `originals` (optional) receives each local vertex's input
// position relative to the grid origin.
Status buildTileMesh(uint32_t tile, std::span<const Triangle> triangles, const VertexSource& vertices,
                     const AttributeLayout& layout, TileMesh& out, std::vector<Vec3d>* originals);

}  // namespace scanpress
