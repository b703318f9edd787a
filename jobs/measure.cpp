#include "jobs/measure.h"

#include <oneapi/tbb/parallel_for.h>
#include <oneapi/tbb/parallel_reduce.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

#include "engine/geometry.h"
#include "engine/quantize.h"
#include "spatial/surface_index.h"

namespace scanpress {

double samplingDensity(const MeasureSettings& s, uint64_t triangles, double area) {
  if (!(area > 0)) return 0;
  if (s.samples > 0) return double(s.samples) / area;
  return s.samples_per_triangle * double(triangles) / area;
}

ErrorAccumulator distancesTo(const SurfaceIndex& surface, std::span<const Vec3d> samples, size_t averaged) {
  std::vector<double> d(samples.size());
  // Several samples per triangle of the surface (a simplified or remeshed result): blocks of nearby samples share
  // Embree gathers (closestMany). About one or two per triangle (lossless codecs, the way back): one query per
  // sample, each starting from the previous answer (samples come in surface order), without closestMany's ~160
  // bytes per triangle: there its speed-up does not pay for its memory, since measure already peaks above the
  // codecs and tiles are measured in parallel. The threshold's measurement: bench/RESULTS.md.
  constexpr double kBatchSamplesPerTriangle = 4;
  const bool batch = double(samples.size()) >= kBatchSamplesPerTriangle * double(surface.triangleCount());
  tbb::parallel_for(tbb::blocked_range<size_t>(0, samples.size(), 1024), [&](const tbb::blocked_range<size_t>& r) {
    if (batch) {
      std::vector<SurfaceIndex::Closest> out(r.size());
      surface.closestMany(samples.subspan(r.begin(), r.size()), out);
      for (size_t i = 0; i < r.size(); ++i) d[r.begin() + i] = out[i].distance;
      return;
    }
    uint32_t hint = UINT32_MAX;
    for (size_t i = r.begin(); i != r.end(); ++i) {
      const auto c = surface.closest(samples[i], hint);
      d[i] = c.distance;
      hint = c.triangle;
    }
  });
  ErrorAccumulator acc;
  averaged = std::min(averaged, d.size());
  for (size_t i = 0; i < averaged; ++i) acc.add(d[i]);
  for (size_t i = averaged; i < d.size(); ++i) acc.addToMax(d[i]);
  return acc;
}

Status measureSurfaces(std::span<const Vec3d> original_positions, std::span<const Triangle> original_triangles,
                       std::span<const Vec3d> decoded_positions, std::span<const Triangle> decoded_triangles,
                       const MeasureSettings& s, double density, uint64_t stream, std::shared_ptr<EmbreeDevice> device,
                       ErrorAccumulator& forward, ErrorAccumulator& backward) {
  SP_ASSIGN_OR_RETURN(SurfaceIndex to_original, SurfaceIndex::build(device, original_positions, original_triangles));
  SP_ASSIGN_OR_RETURN(SurfaceIndex to_decoded, SurfaceIndex::build(device, decoded_positions, decoded_triangles));
  SampleOptions opt;
  opt.density = density;
  opt.seed = s.seed;
  opt.stratified = s.stratified;
  opt.vertices = false;  // appended apart: vertex samples count for the max only (ErrorAccumulator::addToMax)
  opt.stream = stream;
  std::vector<Vec3d> samples;
  sampleSurface(original_positions, original_triangles, opt, samples);
  size_t area_samples = samples.size();
  if (s.vertices) sampleVertices(original_positions, original_triangles, samples);
  forward = distancesTo(to_decoded, samples, area_samples);
  samples.clear();
  opt.stream = stream + 1;
  sampleSurface(decoded_positions, decoded_triangles, opt, samples);
  area_samples = samples.size();
  if (s.vertices) sampleVertices(decoded_positions, decoded_triangles, samples);
  backward = distancesTo(to_original, samples, area_samples);
  return Status::ok();
}

namespace {

constexpr double kInfinity = std::numeric_limits<double>::infinity();

// Squared distance from p to the box (0 inside).
double boxDistanceSquared(const Vec3d& p, const BoundingBox& b) {
  double d2 = 0;
  for (int a = 0; a < 3; ++a) {
    const double d = p[a] < b.lo[a] ? b.lo[a] - p[a] : (p[a] > b.hi[a] ? p[a] - b.hi[a] : 0.0);
    d2 += d * d;
  }
  return d2;
}

// Squared distance between two boxes (0 when they meet), rounded down a little so that it stays a lower bound.
double boxesDistanceSquared(const BoundingBox& x, const BoundingBox& y) {
  double d2 = 0;
  for (int a = 0; a < 3; ++a) {
    const double d = std::max({0.0, x.lo[a] - y.hi[a], y.lo[a] - x.hi[a]});
    d2 += d * d;
  }
  return d2 * (1 - 1e-12);
}

// Area samples per batch: what one batch of samples and their distances may hold.
constexpr double kBatchSamples = 1 << 20;

// One direction of measureChunked: samples of `from`'s chunks in order, against `to`.
Result<ErrorAccumulator> chunkedDirection(const ChunkedSurface& from, const ChunkedSurface& to,
                                          const SampleOptions& opt, bool vertices, ChunkIndexCache& cache) {
  SurfaceSampler sampler(opt);
  ErrorAccumulator acc;
  std::vector<Vec3d> samples;
  std::vector<double> best;
  for (size_t i = 0; i < from.chunks(); ++i) {
    if (from.info(i).triangles == 0) continue;
    SP_ASSIGN_OR_RETURN(auto mesh, from.load(i));
    const std::span<const Triangle> tris(mesh->triangles);
    const auto& p = mesh->positions;
    for (size_t t0 = 0; t0 < tris.size();) {  // batches of about kBatchSamples area samples
      size_t t1 = t0;
      for (double expect = 0; t1 < tris.size() && (t1 == t0 || expect < kBatchSamples); ++t1)
        expect += opt.density * triangleArea(p[tris[t1][0]], p[tris[t1][1]], p[tris[t1][2]]);
      samples.clear();
      sampler.sample(p, tris.subspan(t0, t1 - t0), samples);
      SP_RETURN_IF_ERROR(nearestSquared(to, cache, samples, best));
      for (double d2 : best) acc.add(std::sqrt(d2));
      t0 = t1;
    }
    if (vertices) {  // for the max only; a vertex in two chunks is measured twice, which the max does not see
      samples.clear();
      sampleVertices(p, tris, samples);
      SP_RETURN_IF_ERROR(nearestSquared(to, cache, samples, best));
      for (double d2 : best) acc.addToMax(std::sqrt(d2));
    }
  }
  return acc;
}

}  // namespace

struct ChunkIndexCache::Entry {
  std::shared_ptr<const Mesh> mesh;
  SurfaceIndex index;
  uint64_t bytes = 0, used = 0;
};

uint64_t chunkIndexBytes(const SurfaceChunkInfo& c) {
  // Measured peaks of SurfaceIndex::build (Embree's BVH, the index's float vertices and spheres) plus the chunk's
  // mesh: bench/RESULTS.md, "Measure and render under a memory budget".
  constexpr uint64_t kPerTriangle = 140, kPerVertex = 40;
  return c.triangles * kPerTriangle + c.vertices * kPerVertex;
}

ChunkIndexCache::ChunkIndexCache(const ChunkedSurface& surface, std::shared_ptr<EmbreeDevice> device, uint64_t bytes)
    : surface_(surface), device_(std::move(device)), limit_(bytes), entries_(surface.chunks()) {}

ChunkIndexCache::~ChunkIndexCache() = default;

Result<const SurfaceIndex*> ChunkIndexCache::get(size_t chunk) {
  if (!entries_[chunk]) {
    const uint64_t bytes = chunkIndexBytes(surface_.info(chunk));
    while (held_ > 0 && held_ + bytes > limit_) {  // drop the least recently used
      size_t oldest = SIZE_MAX;
      for (size_t j = 0; j < entries_.size(); ++j)
        if (entries_[j] && (oldest == SIZE_MAX || entries_[j]->used < entries_[oldest]->used)) oldest = j;
      held_ -= entries_[oldest]->bytes;
      entries_[oldest].reset();
    }
    SP_ASSIGN_OR_RETURN(auto mesh, surface_.load(chunk));
    SP_ASSIGN_OR_RETURN(SurfaceIndex index, SurfaceIndex::build(device_, mesh->positions, mesh->triangles));
    entries_[chunk] = std::make_unique<Entry>(Entry{std::move(mesh), std::move(index), bytes, 0});
    held_ += bytes;
    ++builds_;
  }
  entries_[chunk]->used = ++clock_;
  return &entries_[chunk]->index;
}

Status nearestSquared(const ChunkedSurface& surface, ChunkIndexCache& cache, std::span<const Vec3d> points,
                      std::vector<double>& best) {
  best.assign(points.size(), kInfinity);
  if (points.empty()) return Status::ok();
  BoundingBox box;
  for (const Vec3d& p : points) box.extend(p);
  // Chunks nearest to the points' box first (a heap: usually the first few settle every point).
  std::vector<std::pair<double, size_t>> order;
  for (size_t j = 0; j < surface.chunks(); ++j)
    if (surface.info(j).triangles > 0) order.push_back({boxesDistanceSquared(box, surface.info(j).box), j});
  const auto later = [](const auto& a, const auto& b) { return a > b; };
  std::make_heap(order.begin(), order.end(), later);
  double worst = kInfinity;  // the largest best so far
  while (!order.empty()) {
    std::pop_heap(order.begin(), order.end(), later);
    const auto [lower, j] = order.back();
    order.pop_back();
    if (lower >= worst) break;  // no point can find anything nearer in this chunk or any later one
    SP_ASSIGN_OR_RETURN(const SurfaceIndex* index, cache.get(j));
    const BoundingBox& chunk_box = surface.info(j).box;
    tbb::parallel_for(tbb::blocked_range<size_t>(0, points.size(), 1024), [&](const tbb::blocked_range<size_t>& r) {
      uint32_t hint = UINT32_MAX;  // points come in runs of neighbours
      for (size_t k = r.begin(); k != r.end(); ++k) {
        if (!(boxDistanceSquared(points[k], chunk_box) < best[k])) continue;
        const auto c = index->closest(points[k], hint, best[k]);
        if (c.triangle == UINT32_MAX) continue;
        best[k] = c.distance_squared;
        hint = c.triangle;
      }
    });
    worst = tbb::parallel_reduce(
        tbb::blocked_range<size_t>(0, best.size(), 1 << 16), 0.0,
        [&](const tbb::blocked_range<size_t>& r, double m) {
      for (size_t k = r.begin(); k != r.end(); ++k) m = std::max(m, best[k]);
      return m;
        },
        [](double a, double b) { return std::max(a, b); });
  }
  return Status::ok();
}

Result<MeasureResult> measureChunked(const ChunkedSurface& original, const ChunkedSurface& decoded,
                                     const MeasureSettings& s, uint64_t cache_bytes,
                                     std::shared_ptr<EmbreeDevice> device) {
  if (original.triangles() == 0 || decoded.triangles() == 0)
    return makeError(ErrorCode::kUnsupported,
                     "both meshes need triangles to measure a surface distance (a point "
                     "cloud has no surface; measure does not compare point sets)");
  MeasureResult r;
  r.diagonal = original.usedBox().diagonal();
  SampleOptions opt;
  opt.density = samplingDensity(s, original.triangles(), original.area());
  opt.seed = s.seed;
  opt.stratified = s.stratified;
  opt.vertices = false;
  ErrorAccumulator forward, backward;
  {
    ChunkIndexCache cache(decoded, device, cache_bytes);
    opt.stream = 0;
    SP_ASSIGN_OR_RETURN(forward, chunkedDirection(original, decoded, opt, s.vertices, cache));
  }
  {
    ChunkIndexCache cache(original, device, cache_bytes);
    opt.stream = 1;
    SP_ASSIGN_OR_RETURN(backward, chunkedDirection(decoded, original, opt, s.vertices, cache));
  }
  r.forward = statsOf(forward);
  r.backward = statsOf(backward);
  r.symmetric = symmetricOf(r.forward, r.backward);
  return r;
}

Result<MeasureResult> measureMeshes(const Mesh& original, const Mesh& decoded, const MeasureSettings& s,
                                    std::shared_ptr<EmbreeDevice> device) {
  if (original.triangles.empty() || decoded.triangles.empty())
    return makeError(ErrorCode::kUnsupported,
                     "both meshes need triangles to measure a surface distance (a point "
                     "cloud has no surface; measure does not compare point sets)");
  MeasureResult r;
  r.diagonal = usedBoundingBox(original).diagonal();  // as the encoder's: a stray vertex does not stretch it
  // One density for both directions, from the original, so both sample the surfaces alike.
  const double density =
      samplingDensity(s, original.triangles.size(), surfaceArea(original.positions, original.triangles));
  ErrorAccumulator forward, backward;
  SP_RETURN_IF_ERROR(measureSurfaces(original.positions, original.triangles, decoded.positions, decoded.triangles, s,
                                     density, 0, std::move(device), forward, backward));
  r.forward = statsOf(forward);
  r.backward = statsOf(backward);
  r.symmetric = symmetricOf(r.forward, r.backward);
  return r;
}

}  // namespace scanpress
