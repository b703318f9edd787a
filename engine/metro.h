// Metro-style surface sampling and error statistics (Cignoni, Rocchini, Scopigno, "Metro: measuring error on
// simplified surfaces", CGF 1998).
//
// Samples are spread over triangles in proportion to their area at a fixed density (samples per unit area),
// so that samples of several pieces (tiles) of one surface combine into one consistent set. Each triangle
// gets floor(density * area + carry) samples, the carry diffusing the fractional parts in triangle order;
// within a triangle, samples are stratified (a rank-1 lattice over the unit square, folded into the triangle,
// shifted by a per-triangle random offset) or plain Monte-Carlo. Triangle vertices can be added as samples
// too. Everything is seeded: the same mesh, density and seed give the same samples.
//
// Statistics are kept as sums (count, sum, sum of squares, max) so that pieces combine exactly. The mean and
// RMS estimate the area-weighted average over the surface, so only area samples enter them; vertex samples
// (which sit where the error of a lossy mesh is largest, and would bias them up by several percent at the
// default density) count for the max only. Errors are reported in absolute units and relative to a
// bounding-box diagonal. The symmetric figures are the larger of the two directions (as the symmetric
// Hausdorff distance H(A,B) = max(h(A,B), h(B,A)) of the QEM paper).
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "engine/mesh.h"

namespace scanpress {

struct SampleOptions {
  double density = 0;  // samples per unit area
  uint64_t seed = 1;
  bool stratified = true;
  bool vertices = true;  // also sample every vertex used by a triangle (appended after the area samples)
  uint64_t stream = 0;   // distinguishes pieces (e.g. the tile id) so their random offsets differ
};

// sampleSurface in pieces: consecutive calls with consecutive runs of one mesh's triangles (each run indexed into
// its own positions) append exactly the samples one sampleSurface call over the whole mesh would (the carry and
// the triangle numbering continue from call to call). Vertex samples are not appended (opt.vertices is ignored).
class SurfaceSampler {
 public:
  explicit SurfaceSampler(const SampleOptions& opt);
  void sample(std::span<const Vec3d> positions, std::span<const Triangle> triangles, std::vector<Vec3d>& out);

 private:
  SampleOptions opt_;
  uint64_t base_;
  uint64_t next_triangle_ = 0;
  double carry_ = 0;
};

// Appends samples of the triangles to `out`.
void sampleSurface(std::span<const Vec3d> positions, std::span<const Triangle> triangles, const SampleOptions& opt,
                   std::vector<Vec3d>& out);

// Appends every vertex used by a triangle, in index order (what sampleSurface appends with opt.vertices).
void sampleVertices(std::span<const Vec3d> positions, std::span<const Triangle> triangles, std::vector<Vec3d>& out);

double surfaceArea(std::span<const Vec3d> positions, std::span<const Triangle> triangles);

struct ErrorAccumulator {
  uint64_t count = 0;
  double sum = 0, sum_sq = 0, max = 0;
  void add(double d) {
    ++count;
    sum += d;
    sum_sq += d * d;
    if (d > max) max = d;
  }
  // A sample that is not part of the area average (a vertex sample): it counts for the max only.
  void addToMax(double d) {
    if (d > max) max = d;
  }
  void merge(const ErrorAccumulator& o) {
    count += o.count;
    sum += o.sum;
    sum_sq += o.sum_sq;
    if (o.max > max) max = o.max;
  }
  double mean() const { return count ? sum / count : 0.0; }
  double rms() const;
};

struct ErrorStats {
  double mean = 0, rms = 0, max = 0;
  uint64_t samples = 0;
};

inline ErrorStats statsOf(const ErrorAccumulator& a) { return {a.mean(), a.rms(), a.max, a.count}; }
inline ErrorStats symmetricOf(const ErrorStats& f, const ErrorStats& b) {
  return {f.mean > b.mean ? f.mean : b.mean, f.rms > b.rms ? f.rms : b.rms, f.max > b.max ? f.max : b.max,
          f.samples + b.samples};
}

}  // namespace scanpress
