#include "jobs/measure.h"

#include <oneapi/tbb/parallel_for.h>

#include <algorithm>
#include <vector>

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
