// A surface a piece at a time, for `measure`, `render` and the jobs' error pictures under a memory budget.
//
// A ChunkedSurface is a mesh cut into chunks: runs of consecutive triangles, each with the vertices it uses (a
// vertex shared by two chunks is in both), in the mesh's triangle order. Concatenating the chunks' triangles gives
// the mesh's triangles in order with the same corner positions, so what is computed per triangle in order
// (Metro sampling, areas) comes out the same as on the whole mesh, and what is a minimum or maximum over
// triangles (closest points, ray hits, bounds) too.
//
// Sources:
//  - a Mesh in memory: one chunk without a copy, or runs of a given length (copied when loaded);
//  - a mesh file, read once: its vertices go to a scratch file read back through a bounded block cache (in memory
//    when they fit it), and each run of triangles is written to a second scratch file with its vertices;
//  - a container: one chunk per tile, decoded when loaded (positions at cell centres, as `decode` writes them).
// Building one surveys it: every vertex's box, the used vertices' box, the area (summed in triangle order, as
// surfaceArea sums it) and each chunk's box, so that searches can skip chunks far from a point.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "engine/mesh.h"
#include "engine/quantize.h"
#include "engine/status.h"

namespace scanpress {

struct SurfaceChunkInfo {
  uint64_t triangles = 0, vertices = 0;
  BoundingBox box;  // of the chunk's vertices
  // Boxes of runs of kSurfacePartTriangles of its triangles: a curved piece of surface fills little of its box,
  // and the boxes of its parts tell a point far from the piece from one inside its box.
  std::vector<BoundingBox> parts;
};
constexpr uint64_t kSurfacePartTriangles = 1024;

class ChunkedSurface {
 public:
  class Source;  // how chunks are loaded (chunked_surface.cpp)

  // `mesh` whole, as one chunk; it must outlive the surface.
  static ChunkedSurface whole(const Mesh& mesh);
  // Runs of `chunk_triangles` triangles of `mesh` (at least 1), copied when loaded; `mesh` must outlive it.
  static ChunkedSurface pieces(const Mesh& mesh, uint64_t chunk_triangles);
  // `path` read once into scratch files under `scratch_parent` (empty: the system temp directory), in runs of
  // `chunk_triangles` triangles; the vertex cache holds at most `cache_bytes`.
  static Result<ChunkedSurface> fromMeshFile(const std::string& path, uint64_t chunk_triangles, uint64_t cache_bytes,
                                             const std::string& scratch_parent);
  // The tiles of container `path`, decoded once here to survey them and again on each load.
  static Result<ChunkedSurface> fromContainer(const std::string& path);

  ChunkedSurface(ChunkedSurface&&) noexcept;
  ChunkedSurface& operator=(ChunkedSurface&&) noexcept;
  ~ChunkedSurface();

  size_t chunks() const { return info_.size(); }
  const SurfaceChunkInfo& info(size_t i) const { return info_[i]; }
  // Chunk i (thread-safe). Only vertices its triangles use, except for whole() and container tiles, which keep
  // the vertices they have.
  Result<std::shared_ptr<const Mesh>> load(size_t i) const;

  uint64_t triangles() const { return triangles_; }
  double area() const { return area_; }
  const BoundingBox& box() const { return box_; }           // every vertex (boundingBox of the mesh)
  const BoundingBox& usedBox() const { return used_box_; }  // usedBoundingBox of the mesh

 private:
  ChunkedSurface() = default;
  void addChunk(const Mesh& chunk);  // surveys a chunk (in order)

  std::unique_ptr<Source> source_;
  std::vector<SurfaceChunkInfo> info_;
  uint64_t triangles_ = 0;
  double area_ = 0;
  BoundingBox box_, used_box_;
};

// Memory a chunk's search index takes with its mesh (for the index cache's accounting and the budget checks).
uint64_t searchIndexBytes(uint64_t triangles, uint64_t vertices);

// A file as a ChunkedSurface within `memory_budget` (0: no limit): a container's tiles, or a mesh file in runs
// whose search indexes fit a sixteenth of the budget, its vertex cache an eighth. A container whose largest tile's
// index would not fit the index cache (half the budget) is refused, naming the budget it needs.
Result<ChunkedSurface> openSurface(const std::string& path, uint64_t memory_budget, const std::string& scratch_parent);
// The index cache's share of a budget for measure and render (half; no limit for 0).
uint64_t surfaceCacheBytes(uint64_t memory_budget);
// Whether measuring or rendering these files must go a chunk at a time under `memory_budget`: a container
// always does (its tiles are its chunks), mesh files when their estimate exceeds the budget.
bool needsChunks(const std::vector<std::string>& paths, uint64_t memory_budget);

// The in-memory Mesh of a file for measure and render: a container is decoded and welded (as `decode` writes it).
Result<Mesh> readSurfaceFile(const std::string& path);
bool isContainerPath(const std::string& path);

// What measuring or rendering a surface whole takes in memory per triangle: mesh, search index, samples.
constexpr uint64_t kInMemoryBytesPerTriangle = 200;
// What measuring or rendering `path` whole would take in memory, estimated from its size (kInMemoryBytesPerTriangle;
// a container from its index counts).
uint64_t inMemorySurfaceBytes(const std::string& path);

}  // namespace scanpress
