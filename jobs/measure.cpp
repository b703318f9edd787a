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
#include "spatial/surface_morton.h"

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

// Whether a box at squared distance `lower` may hold a point nearer than `best` (squared): with a margin for the
// rounding of computed distances, `slack` (absolute), so that a triangle whose computed distance is below `best`
// is never skipped.
bool mayBeNearer(double lower, double best, double slack) {
  return lower < best || std::sqrt(lower) < std::sqrt(best) + slack;
}

// What measure refuses: a mesh without triangles (both the whole-mesh and the chunked measurement).
Status needSurfaces(uint64_t original_triangles, uint64_t decoded_triangles) {
  if (original_triangles > 0 && decoded_triangles > 0) return Status::ok();
  return makeError(ErrorCode::kUnsupported,
                   "both meshes need triangles to measure a surface distance (a point "
                   "cloud has no surface; measure does not compare point sets)");
}

// Area samples per batch: a 64th of the index cache (a sample takes about 64 bytes with its distance, group and
// Morton order), within [2^12, 2^20].
double batchSamples(uint64_t cache_bytes) {
  return double(std::clamp<uint64_t>(cache_bytes / 64 / 64, 4096, 1 << 20));
}

// One direction of measureChunked: samples of `from`'s chunks in order, against `to`.
Result<ErrorAccumulator> chunkedDirection(const ChunkedSurface& from, const ChunkedSurface& to,
                                          const SampleOptions& opt, bool vertices, ChunkIndexCache& cache,
                                          double batch) {
  SurfaceSampler sampler(opt);
  ErrorAccumulator acc;
  std::vector<Vec3d> samples;
  std::vector<double> best;
  for (size_t i = 0; i < from.chunks(); ++i) {
    if (from.info(i).triangles == 0) continue;
    SP_ASSIGN_OR_RETURN(auto mesh, from.load(i));
    const std::span<const Triangle> tris(mesh->triangles);
    const auto& p = mesh->positions;
    for (size_t t0 = 0; t0 < tris.size();) {  // batches of about `batch` area samples
      size_t t1 = t0;
      for (double expect = 0; t1 < tris.size() && (t1 == t0 || expect < batch); ++t1)
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

ChunkIndexCache::ChunkIndexCache(const ChunkedSurface& surface, std::shared_ptr<EmbreeDevice> device, uint64_t bytes)
    : surface_(surface), device_(std::move(device)), limit_(bytes), entries_(surface.chunks()) {}

ChunkIndexCache::~ChunkIndexCache() = default;

Result<const SurfaceIndex*> ChunkIndexCache::get(size_t chunk) {
  if (!entries_[chunk]) {
    const uint64_t bytes = searchIndexBytes(surface_.info(chunk).triangles, surface_.info(chunk).vertices);
    while (held_ > 0 && held_ + bytes > limit_) {  // drop the least recently used
      size_t oldest = SIZE_MAX;
      for (size_t j = 0; j < entries_.size(); ++j)
        if (entries_[j] && (oldest == SIZE_MAX || entries_[j]->used < entries_[oldest]->used)) oldest = j;
      held_ -= entries_[oldest]->bytes;
      entries_[oldest].reset();
    }
    SP_ASSIGN_OR_RETURN(auto mesh, surface_.load(chunk));
    const BoundingBox& box = surface_.box();
    const Vec3d center = vmul(vadd(box.lo, box.hi), 0.5);  // one origin for every chunk (as render needs)
    SP_ASSIGN_OR_RETURN(SurfaceIndex index, SurfaceIndex::build(device_, mesh->positions, mesh->triangles, &center));
    entries_[chunk] = std::make_unique<Entry>(Entry{std::move(mesh), std::move(index), bytes, 0});
    held_ += bytes;
    ++builds_;
  }
  entries_[chunk]->used = ++clock_;
  return &entries_[chunk]->index;
}

Status nearestSquared(const ChunkedSurface& surface, ChunkIndexCache& cache, std::span<const Vec3d> points,
                      std::vector<double>& best) {
  const size_t n = points.size();
  best.assign(n, kInfinity);
  std::vector<uint32_t> chunks;  // those with triangles
  for (size_t j = 0; j < surface.chunks(); ++j)
    if (surface.info(j).triangles > 0) chunks.push_back(static_cast<uint32_t>(j));
  if (n == 0 || chunks.empty()) return Status::ok();
  // Rounding of distances computed from coordinates this large (a few ulps of the largest, generously).
  double magnitude = 0;
  for (int a = 0; a < 3; ++a)
    magnitude = std::max({magnitude, std::fabs(surface.box().lo[a]), std::fabs(surface.box().hi[a])});
  for (const Vec3d& p : points)
    for (int a = 0; a < 3; ++a)
      if (std::isfinite(p[a])) magnitude = std::max(magnitude, std::fabs(p[a]));
  const double slack = magnitude * 64 * std::numeric_limits<double>::epsilon();
  // Groups of neighbouring points (consecutive along a Morton curve), each with its box: a group looks only at
  // chunks near its own box, so a batch spread over a scan does not pull in every chunk its box meets.
  BoundingBox all;
  for (const Vec3d& p : points) all.extend(p);
  const double extent = all.empty() ? 0.0 : all.maxExtent();
  int index_bits = 1;
  while ((uint64_t(1) << index_bits) < n) ++index_bits;
  std::vector<uint64_t> order, scratch;
  surface::mortonOrder(points, extent > 0 ? 1024 / extent : 1.0, index_bits, order, scratch);
  const uint64_t mask = (uint64_t(1) << index_bits) - 1;
  std::vector<uint32_t> member(n);
  for (size_t k = 0; k < n; ++k) member[k] = static_cast<uint32_t>(order[k] & mask);
  std::vector<uint64_t>().swap(order);
  std::vector<uint64_t>().swap(scratch);
  constexpr size_t kGroup = 512;
  struct Group {
    size_t begin, end;
    BoundingBox box;
    std::vector<uint32_t> visited;  // chunks searched
    uint32_t next = UINT32_MAX;     // the chunk to search next
  };
  std::vector<Group> groups;
  for (size_t b = 0; b < n; b += kGroup) {
    Group g{b, std::min(n, b + kGroup), {}, {}, UINT32_MAX};
    for (size_t k = g.begin; k < g.end; ++k) g.box.extend(points[member[k]]);
    groups.push_back(std::move(g));
  }
  // Rounds: each group picks the nearest chunk it has not searched whose box is nearer than its farthest point's
  // best so far; each picked chunk is searched once for every group that picked it. A group is done when no chunk
  // is left nearer than its farthest best: then every point's best is exact (no triangle of an unsearched chunk is
  // nearer to a point than the chunk's box is to the group's box).
  std::vector<std::vector<uint32_t>> wanted_by(surface.chunks());
  for (;;) {
    tbb::parallel_for(size_t(0), groups.size(), [&](size_t gi) {
      Group& g = groups[gi];
      double worst = 0;
      for (size_t k = g.begin; k < g.end; ++k) worst = std::max(worst, best[member[k]]);
      double nearest = worst;
      g.next = UINT32_MAX;
      for (uint32_t j : chunks) {
        const SurfaceChunkInfo& c = surface.info(j);
        if (!mayBeNearer(boxesDistanceSquared(g.box, c.box), nearest, slack)) continue;
        double lower = kInfinity;
        for (const BoundingBox& part : c.parts) lower = std::min(lower, boxesDistanceSquared(g.box, part));
        if ((g.next == UINT32_MAX ? mayBeNearer(lower, nearest, slack) : lower < nearest) &&
            std::find(g.visited.begin(), g.visited.end(), j) == g.visited.end())
          nearest = lower, g.next = j;
      }
    });
    std::vector<uint32_t> picked;
    for (uint32_t gi = 0; gi < groups.size(); ++gi) {
      Group& g = groups[gi];
      if (g.next == UINT32_MAX) continue;
      if (wanted_by[g.next].empty()) picked.push_back(g.next);
      wanted_by[g.next].push_back(gi);
      g.visited.push_back(g.next);
    }
    if (picked.empty()) break;
    // Chunks whose index is built already first, so that the round does not drop one it needs later.
    std::stable_partition(picked.begin(), picked.end(), [&](uint32_t j) { return cache.holds(j); });
    for (uint32_t j : picked) {
      SP_ASSIGN_OR_RETURN(const SurfaceIndex* index, cache.get(j));
      const BoundingBox& chunk_box = surface.info(j).box;
      const std::vector<uint32_t>& wanting = wanted_by[j];
      tbb::parallel_for(size_t(0), wanting.size(), [&](size_t w) {
        const Group& g = groups[wanting[w]];
        uint32_t hint = UINT32_MAX;  // neighbours along the curve
        for (size_t m = g.begin; m < g.end; ++m) {
          const uint32_t k = member[m];
          if (!mayBeNearer(boxDistanceSquared(points[k], chunk_box), best[k], slack)) continue;
          const auto c = index->closest(points[k], hint, best[k]);
          if (c.triangle == UINT32_MAX) continue;
          best[k] = c.distance_squared;
          hint = c.triangle;
        }
      });
      wanted_by[j].clear();
    }
  }
  return Status::ok();
}

Result<MeasureResult> measureChunked(const ChunkedSurface& original, const ChunkedSurface& decoded,
                                     const MeasureSettings& s, uint64_t cache_bytes,
                                     std::shared_ptr<EmbreeDevice> device) {
  SP_RETURN_IF_ERROR(needSurfaces(original.triangles(), decoded.triangles()));
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
    SP_ASSIGN_OR_RETURN(forward,
                        chunkedDirection(original, decoded, opt, s.vertices, cache, batchSamples(cache_bytes)));
  }
  {
    ChunkIndexCache cache(original, device, cache_bytes);
    opt.stream = 1;
    SP_ASSIGN_OR_RETURN(backward,
                        chunkedDirection(decoded, original, opt, s.vertices, cache, batchSamples(cache_bytes)));
  }
  r.forward = statsOf(forward);
  r.backward = statsOf(backward);
  r.symmetric = symmetricOf(r.forward, r.backward);
  return r;
}

Result<MeasureResult> measureMeshes(const Mesh& original, const Mesh& decoded, const MeasureSettings& s,
                                    std::shared_ptr<EmbreeDevice> device) {
  SP_RETURN_IF_ERROR(needSurfaces(original.triangles.size(), decoded.triangles.size()));
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
