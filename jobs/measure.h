// Surface distance between two meshes, Metro-style: area-weighted samples on each surface, exact closest-point
// distances to the other (Embree), in both directions. Distances are computed in parallel and accumulated in
// sample order, so the numbers are the same at any thread count.
#pragma once

#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "engine/mesh.h"
#include "engine/metro.h"
#include "engine/status.h"
#include "jobs/chunked_surface.h"

namespace scanpress {

class EmbreeDevice;
class SurfaceIndex;

struct MeasureSettings {
  bool enabled = false;             // in jobs: measure every encode (decode in memory, measure, discard)
  double samples_per_triangle = 2;  // sampling density: this many samples per triangle of the original, on average
  uint64_t samples = 0;             // if > 0: about this many samples per direction instead
  uint64_t seed = 1;
  bool stratified = true;  // stratified within each triangle (else Monte-Carlo)
  bool vertices = true;    // vertices are samples too (for the max; mean and RMS are of the area samples)
  // Pictures (jobs): a render of the decoded scan colored by distance to the original.
  bool render = false;
  int render_width = 800, render_height = 600;
  double view_azimuth = 30, view_elevation = 20;  // degrees
  double scale_max = 0;  // top of the color bar in units of the diagonal, the same for every picture; 0: per picture
};

struct MeasureResult {
  double diagonal = 0;  // of the original's bounding box
  ErrorStats forward;   // original -> decoded
  ErrorStats backward;  // decoded -> original
  ErrorStats symmetric;
};

// Samples per unit area for a surface of `triangles` triangles and `area` (settings: per triangle or total).
double samplingDensity(const MeasureSettings& s, uint64_t triangles, double area);

// Distances from `samples` to the surface, accumulated in sample order (parallel queries). The first
// `averaged` samples (area samples) enter the count, mean and RMS; the rest (vertex samples) the max only.
ErrorAccumulator distancesTo(const SurfaceIndex& surface, std::span<const Vec3d> samples, size_t averaged = SIZE_MAX);

// The core of every measurement: samples on the original (stream `stream`) queried against the decoded surface,
// and samples on the decoded surface (stream `stream + 1`) against the original, at `density` samples per unit
// area. Accumulates into `forward` and `backward`.
Status measureSurfaces(std::span<const Vec3d> original_positions, std::span<const Triangle> original_triangles,
                       std::span<const Vec3d> decoded_positions, std::span<const Triangle> decoded_triangles,
                       const MeasureSettings& settings, double density, uint64_t stream,
                       std::shared_ptr<EmbreeDevice> device, ErrorAccumulator& forward, ErrorAccumulator& backward);

// The indexes of a ChunkedSurface's chunks, built when first asked for and kept while they fit `bytes` (the least
// recently used is dropped first; the one asked for is always kept). Not thread-safe; the indexes are.
class ChunkIndexCache {
 public:
  ChunkIndexCache(const ChunkedSurface& surface, std::shared_ptr<EmbreeDevice> device, uint64_t bytes);
  ~ChunkIndexCache();
  Result<const SurfaceIndex*> get(size_t chunk);
  bool holds(size_t chunk) const { return entries_[chunk] != nullptr; }
  uint64_t builds() const { return builds_; }

 private:
  struct Entry;
  const ChunkedSurface& surface_;
  std::shared_ptr<EmbreeDevice> device_;
  uint64_t limit_, held_ = 0, clock_ = 0, builds_ = 0;
  std::vector<std::unique_ptr<Entry>> entries_;  // per chunk; null when not built
};

// The squared distance from each point to the nearest triangle of `surface` (infinity when it has none), exact:
// groups of neighbouring points search the chunks nearest to their box first, each point only where the chunk's
// box is nearer than its best so far, until no chunk left can be nearer for any point of the group.
Status nearestSquared(const ChunkedSurface& surface, ChunkIndexCache& cache, std::span<const Vec3d> points,
                      std::vector<double>& best);

// measureMeshes a chunk at a time: the same samples in the same order and the same exact distances, so the same
// numbers, bit for bit, as measureMeshes on the whole meshes; memory is the cache's `cache_bytes`, a chunk and its
// samples.
Result<MeasureResult> measureChunked(const ChunkedSurface& original, const ChunkedSurface& decoded,
                                     const MeasureSettings& settings, uint64_t cache_bytes,
                                     std::shared_ptr<EmbreeDevice> device);

// Measures `decoded` against `original` (whole meshes in memory).
Result<MeasureResult> measureMeshes(const Mesh& original, const Mesh& decoded, const MeasureSettings& settings,
                                    std::shared_ptr<EmbreeDevice> device);

}  // namespace scanpress
