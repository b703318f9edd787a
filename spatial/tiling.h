// Spatial tiling of a scan on its global grid.
//
// Triangles are assigned to tiles by centroid: the integer centroid floor((q0 + q1 + q2) / 3) of the quantized
// corners falls in exactly one fine cell (cells are half-open cubes of 2^shift grid units), and every fine cell
// belongs to one tile. Tiles come from an octree over the grid: a node is split while it holds more than the
// target triangle count, so dense regions get smaller tiles and empty space costs nothing; small sibling leaves
// are merged greedily in Morton order up to the target, so a split does not leave a spray of tiny tiles.
//
// The histogram is multi-resolution: its first level has cells sized from the triangle count; a cell that holds
// more than the target is refined (16x finer per axis) and the centroids inside it are counted again at the finer
// level (the caller feeds them once more per round, from its spill). A scan with a dense detail patch thus gets
// small tiles there without paying for fine cells everywhere. A tile exceeds the target only when one cell at the
// finest level (2^(bits-21) grid units) alone does.
//
// OpenVDB grids (sparse, hierarchical) hold the histogram of centroids per fine cell and the tile index (fine
// cell -> tile id); they stay inside tiling.cpp. The same histogram gives the same tiles: tile ids follow the
// octree in Morton order, so tiles with near ids are near in space.
//
// Thread safety: TileHistogram::add is not thread-safe. A built TileIndex is read-only; tileOf may be called from
// many threads at once.
#pragma once

#include <cstdint>
#include <memory>
#include <span>
#include <vector>

#include "engine/mesh.h"

namespace scanpress {

// The integer centroid of a triangle over quantized positions.
inline Vec3u triangleCentroid(const Vec3u& a, const Vec3u& b, const Vec3u& c) {
  return {static_cast<uint32_t>((uint64_t(a[0]) + b[0] + c[0]) / 3),
          static_cast<uint32_t>((uint64_t(a[1]) + b[1] + c[1]) / 3),
          static_cast<uint32_t>((uint64_t(a[2]) + b[2] + c[2]) / 3)};
}

class TileHistogram {
 public:
  // Chooses the fine cell size for `total_triangles` and `target` on a grid of `grid_bits` bits.
  TileHistogram(int grid_bits, uint64_t total_triangles, uint64_t target);
  ~TileHistogram();
  TileHistogram(TileHistogram&&) noexcept;
  TileHistogram& operator=(TileHistogram&&) noexcept;

  void add(const Vec3u& centroid);
  // Refinement round: marks the overfull cells of the finest level as refined and opens a finer level. Returns
  // false when there is nothing to refine; otherwise the caller passes every centroid to addRefined once.
  bool beginRefinement();
  void addRefined(const Vec3u& centroid);

 private:
  friend class TileIndex;
  struct Impl;
  std::unique_ptr<Impl> impl_;
  int grid_bits_;
  int shift_;
  uint64_t target_;
};

struct TileInfo {
  uint32_t id = 0;
  uint64_t triangles = 0;  // triangles whose centroid lies in the tile
  Vec3u lo{0, 0, 0};       // grid-unit bounds of the tile's cells (inclusive)
  Vec3u hi{0, 0, 0};
};

class TileIndex {
 public:
  static TileIndex build(const TileHistogram& histogram);
  ~TileIndex();
  TileIndex(TileIndex&&) noexcept;
  TileIndex& operator=(TileIndex&&) noexcept;

  // Tile of a triangle centroid; UINT32_MAX for a cell that held no centroid when the index was built.
  uint32_t tileOf(const Vec3u& centroid) const;
  std::span<const TileInfo> tiles() const { return tiles_; }

 private:
  TileIndex() = default;
  struct Impl;
  std::unique_ptr<Impl> impl_;
  std::vector<TileInfo> tiles_;
};

}  // namespace scanpress
