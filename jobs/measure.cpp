#include "jobs/measure.h"

#include <oneapi/tbb/parallel_for.h>

#include <nlohmann/json.hpp>
#include <vector>

#include "engine/quantize.h"
#include "spatial/surface_index.h"

namespace scanpress {

double samplingDensity(const MeasureSettings& s, uint64_t triangles, double area) {
  if (!(area > 0)) return 0;
  if (s.samples > 0) return double(s.samples) / area;
  return s.samples_per_triangle * double(triangles) / area;
}

ErrorAccumulator distancesTo(const SurfaceIndex& surface, std::span<const Vec3d> samples) {
  std::vector<double> d(samples.size());
  // Samples come in surface order: each query starts from the previous answer's triangle (a tight bound).
  tbb::parallel_for(tbb::blocked_range<size_t>(0, samples.size(), 1024), [&](const tbb::blocked_range<size_t>& r) {
    uint32_t hint = UINT32_MAX;
    for (size_t i = r.begin(); i != r.end(); ++i) {
      const auto c = surface.closest(samples[i], hint);
      d[i] = c.distance;
      hint = c.triangle;
    }
  });
  ErrorAccumulator acc;
  for (double x : d) acc.add(x);
  return acc;
}

Result<MeasureResult> measureMeshes(const Mesh& original, const Mesh& decoded, const MeasureSettings& s,
                                    std::shared_ptr<EmbreeDevice> device) {
  if (original.triangles.empty() || decoded.triangles.empty())
    return makeError(ErrorCode::kInvalidArgument, "both meshes need triangles to measure a surface distance");
  MeasureResult r;
  r.diagonal = boundingBox(original).diagonal();
  SP_ASSIGN_OR_RETURN(SurfaceIndex to_original, SurfaceIndex::build(device, original.positions, original.triangles));
  SP_ASSIGN_OR_RETURN(SurfaceIndex to_decoded, SurfaceIndex::build(device, decoded.positions, decoded.triangles));
  // One density for both directions, from the original, so both sample the surfaces alike.
  SampleOptions opt;
  opt.density = samplingDensity(s, original.triangles.size(), surfaceArea(original.positions, original.triangles));
  opt.seed = s.seed;
  opt.stratified = s.stratified;
  opt.vertices = s.vertices;
  std::vector<Vec3d> samples;
  sampleSurface(original.positions, original.triangles, opt, samples);
  r.forward = statsOf(distancesTo(to_decoded, samples));
  samples.clear();
  opt.stream = 1;
  sampleSurface(decoded.positions, decoded.triangles, opt, samples);
  r.backward = statsOf(distancesTo(to_original, samples));
  r.symmetric = symmetricOf(r.forward, r.backward);
  return r;
}

std::string measureJson(const MeasureResult& r) {
  auto side = [&](const ErrorStats& e) {
    const double d = r.diagonal > 0 ? r.diagonal : 1.0;
    return nlohmann::json{{"mean", e.mean},
                          {"rms", e.rms},
                          {"max", e.max},
                          {"samples", e.samples},
                          {"mean_relative", e.mean / d},
                          {"rms_relative", e.rms / d},
                          {"max_relative", e.max / d}};
  };
  nlohmann::json j = {{"diagonal", r.diagonal},
                      {"samples", r.forward.samples + r.backward.samples},
                      {"forward", side(r.forward)},
                      {"backward", side(r.backward)},
                      {"symmetric", side(r.symmetric)}};
  return j.dump(2) + "\n";
}

}  // namespace scanpress
