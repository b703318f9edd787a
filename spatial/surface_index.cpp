#include "spatial/surface_index.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <mutex>
#include <vector>

#include "engine/geometry.h"
#include "spatial/surface_clusters.h"
#include "spatial/surface_index_internal.h"
#include "spatial/surface_morton.h"

namespace scanpress {

using namespace surface;

SurfaceIndex::SurfaceIndex(SurfaceIndex&&) noexcept = default;
SurfaceIndex& SurfaceIndex::operator=(SurfaceIndex&&) noexcept = default;
SurfaceIndex::~SurfaceIndex() = default;

size_t SurfaceIndex::triangleCount() const { return impl_->triangles.size(); }

Result<SurfaceIndex> SurfaceIndex::build(std::shared_ptr<EmbreeDevice> device, std::span<const Vec3d> positions,
                                         std::span<const Triangle> triangles, const Vec3d* origin) {
  SurfaceIndex index;
  index.impl_ = std::make_unique<Impl>();
  Impl& m = *index.impl_;
  m.device = std::move(device);
  m.positions = positions;
  m.triangles = triangles;
  for (const auto& t : triangles)
    for (uint32_t v : t)
      if (v >= positions.size()) return makeError(ErrorCode::kInvalidArgument, "triangle index out of range");
  // Origin at the bounding-box center keeps float coordinates small and precise.
  Vec3d lo{1e300, 1e300, 1e300}, hi{-1e300, -1e300, -1e300};
  for (const auto& p : positions)
    for (int a = 0; a < 3; ++a) lo[a] = std::min(lo[a], p[a]), hi[a] = std::max(hi[a], p[a]);
  double extent = 0;
  if (!positions.empty())
    for (int a = 0; a < 3; ++a) m.origin[a] = 0.5 * (lo[a] + hi[a]), extent = std::max(extent, hi[a] - lo[a]);
  if (origin && !positions.empty()) {  // the slack covers the float rounding of coordinates this far from it
    m.origin = *origin;
    for (int a = 0; a < 3; ++a)
      extent = std::max({extent, 2 * std::fabs(lo[a] - m.origin[a]), 2 * std::fabs(hi[a] - m.origin[a])});
  }
  m.slack = static_cast<float>(extent * 4.0 * std::numeric_limits<float>::epsilon()) + 1e-30f;
  m.vertices.resize(positions.size() * 3 + 4);
  for (size_t i = 0; i < positions.size(); ++i)
    for (int a = 0; a < 3; ++a) m.vertices[3 * i + a] = static_cast<float>(positions[i][a] - m.origin[a]);

  // Bounding spheres (circumcenter of the bounding box of the corners), inflated by the float rounding: a
  // candidate whose sphere is farther than the best distance so far is rejected without the exact test.
  m.spheres.resize(triangles.size() * 4);
  for (size_t t = 0; t < triangles.size(); ++t) {
    Vec3d c{0, 0, 0};
    for (int a = 0; a < 3; ++a) {
      double lo_a = 1e300, hi_a = -1e300;
      for (uint32_t v : triangles[t]) lo_a = std::min(lo_a, positions[v][a]), hi_a = std::max(hi_a, positions[v][a]);
      c[a] = 0.5 * (lo_a + hi_a);
    }
    double r = 0;
    for (uint32_t v : triangles[t]) r = std::max(r, vlen(vsub(positions[v], c)));
    for (int a = 0; a < 3; ++a) m.spheres[4 * t + a] = static_cast<float>(c[a] - m.origin[a]);
    m.spheres[4 * t + 3] = static_cast<float>(r) * (1.0f + 8 * std::numeric_limits<float>::epsilon()) + 2 * m.slack;
    m.mean_radius += r;
  }
  if (!triangles.empty()) m.mean_radius /= double(triangles.size());

  SP_ASSIGN_OR_RETURN(m.scene, surface::triangleScene(m));
  return index;
}

namespace {

// Points are ordered by the Morton key of their cell (kCellRadii mean triangle radii); runs are maximal stretches
// of that order whose box has a half-diagonal of at most kRunRadii. The gather reaches beyond the run's points by
// at least kReachMin radii, or by 1.25 times the largest distance in the last run done (the gathers are one run
// ahead: that is the run before the previous), at most kReachMax. The values: bench/RESULTS.md.
constexpr double kCellRadii = 1.0, kRunRadii = 1.5, kReachMin = 0.1, kReachMax = 2.0;
// A run of at most kDirectPoints points bounds its clusters' blocks where they are (its gather prefetches their
// corners too); a larger run first copies out the triangles that may lie within its reach, so that each of its
// points bounds fewer.
constexpr size_t kDirectPoints = 8;

}  // namespace

void SurfaceIndex::closestMany(std::span<const Vec3d> points, std::span<Closest> out) const {
  const Impl& m = *impl_;
  if (!m.triangles.empty() && points.size() >= 2)
    std::call_once(impl_->clusters_built, [this] { impl_->clusters = surface::buildClusters(*impl_); });
  const surface::ClusterSet* set = m.clusters.get();
  if (m.triangles.empty() || points.size() < 2 || !set) {
    for (size_t i = 0; i < points.size(); ++i) out[i] = closest(points[i]);
    return;
  }
  const double inv_cell = 1 / (kCellRadii * m.mean_radius), run_half = kRunRadii * m.mean_radius;
  const int index_bits = std::max(1, 64 - __builtin_clzll(points.size() - 1));
  const uint64_t index_mask = (uint64_t(1) << index_bits) - 1;
  std::vector<uint64_t> order, scratch;
  mortonOrder(points, inv_cell, index_bits, order, scratch);
  auto at = [&](size_t k) { return size_t(order[k] & index_mask); };  // the point at place k of the order
  auto finite = [&](size_t k) { return !(order[k] >> 63); };

  // Runs first; each run's gather is made one run ahead, so that the memory its clusters need is on its way while
  // the run before is processed.
  struct Run {
    size_t i, j;  // order[i, j)
    Vec3d c;      // center of the points' box
    double half;  // half-diagonal of that box
  };
  std::vector<Run> runs;
  for (size_t i = 0, j = 0; i < order.size(); i = j) {
    Vec3d lo = points[at(i)], hi = lo;
    for (j = i + 1; j < order.size() && finite(i); ++j) {
      const Vec3d& p = points[at(j)];
      if (!growWithin(lo, hi, p, p, run_half)) break;
    }
    runs.push_back({i, j, vmul(vadd(lo, hi), 0.5), 0.5 * vlen(vsub(hi, lo))});
  }
  // One gather of radius R around a run's center c reaches every cluster holding a triangle within R of c. For a
  // point p whose best distance among their triangles is b, a nearer triangle would lie within |p - c| + b of c:
  // when that is at most R, b is p's answer; otherwise p gets its own gather, of radius b around p.
  struct Gathered {
    double reach = 0;   // R
    float cf[3] = {};   // c relative to the origin, in float
    float reach_f = 0;  // R in float, with the rounding of c and of Embree's sphere-box tests
    std::vector<uint32_t> clusters;
  };
  double extra = kReachMin * m.mean_radius;
  auto gather = [&](const Vec3d& c, double reach, Gathered& g, bool corners) {
    g.clusters.clear();
    g.reach = reach;
    for (int a = 0; a < 3; ++a) g.cf[a] = static_cast<float>(c[a] - m.origin[a]);
    // Float rounding: well inside 16 slacks plus 64 ulps of |c|.
    const float margin_c = 16 * m.slack + 64 * kEps * (std::abs(g.cf[0]) + std::abs(g.cf[1]) + std::abs(g.cf[2]));
    g.reach_f = static_cast<float>(g.reach) * (1 + 4 * kEps) + margin_c;
    gatherClusters(*set, g.cf, g.reach_f, corners, g.clusters);
  };
  auto inPlace = [](const Run& run) { return run.j - run.i <= kDirectPoints; };  // bounds its clusters in place
  auto gatherRun = [&](const Run& run, Gathered& g) {
    if (!finite(run.i)) return g.clusters.clear();  // not finite: queried alone
    gather(run.c, run.half + extra, g, inPlace(run));
  };
  Gathered current, next, own;
  std::vector<float> rows, bounds;
  std::vector<const float*> blocks;
  std::vector<uint32_t> slots;
  uint32_t hint = UINT32_MAX;
  if (!runs.empty()) gatherRun(runs[0], next);
  for (size_t r = 0; r < runs.size(); ++r) {
    std::swap(current, next);
    if (r + 1 < runs.size()) gatherRun(runs[r + 1], next);
    const size_t i = runs[r].i, j = runs[r].j;
    if (!finite(i)) {
      out[at(i)] = closest(points[at(i)]);
      continue;
    }
    const Vec3d& c = runs[r].c;
    const double reach = current.reach;
    // The run's candidates: blocks of kLanes plane records (`blocks`) and the slot of each lane (`slots`; the
    // first `count` lanes). A small run takes its clusters' blocks in place; a larger run copies out the
    // triangles that may lie within R of c (by their bound).
    size_t gathered = 0;  // lanes of the run's clusters: room for every candidate
    for (uint32_t k : current.clusters) gathered += (set->first[k + 1] - set->first[k]) * kLanes;
    if (slots.size() < gathered) slots.resize(gathered), rows.resize(gathered * 16), bounds.resize(gathered);
    blocks.clear();
    const size_t count = inPlace(runs[r]) ? candidatesInPlace(*set, current.clusters, blocks, slots.data())
                                          : candidatesCopiedOut(*set, current.clusters, current.cf,
                                                                current.reach_f * current.reach_f * (1 + 16 * kEps),
                                                                rows.data(), blocks, slots.data());
    double farthest = 0;
    for (size_t k = i; k < j; ++k) {
      const Vec3d& p = points[at(k)];
      Closest& o = out[at(k)];
      o.distance = std::numeric_limits<double>::infinity();  // squared until the end
      o.triangle = UINT32_MAX;
      const float pf[3] = {static_cast<float>(p[0] - m.origin[0]), static_cast<float>(p[1] - m.origin[1]),
                           static_cast<float>(p[2] - m.origin[2])};
      // Float rounding of the records, p, and the dot products: well inside this margin.
      const float margin = 16 * m.slack + 64 * kEps * (std::abs(pf[0]) + std::abs(pf[1]) + std::abs(pf[2]));
      // Bound below which a triangle may still be nearer than the best so far (squared, rounded up).
      float below = std::numeric_limits<float>::infinity();
      auto test = [&](size_t slot) {
        if (set->ids[slot] == UINT32_MAX) return;  // an unused lane
        const Vec3d* t = &set->corners[3 * slot];
        const Vec3d q = closestPointOnTriangle(p, t[0], t[1], t[2]);
        const double d2 = vdot(vsub(q, p), vsub(q, p));
        if (d2 < o.distance) {
          o.distance = d2, o.point = q, o.triangle = set->ids[slot];
          const float r = static_cast<float>(std::sqrt(d2)) * (1 + 4 * kEps) + margin;
          below = r * r * (1 + 16 * kEps);
        }
      };
      if (count) {
        // The least bound first (nearly always the answer), then any bound still below the best distance.
        const size_t first = boundsAndLeast(blocks.data(), blocks.size(), pf, bounds.data());
        if (first < count) test(slots[first]);
        const Lanes* bound = reinterpret_cast<const Lanes*>(bounds.data());
        for (size_t b = 0; b < blocks.size(); ++b)
          for (unsigned bits = lanesAtMost(bound[b], Lanes{} + below); bits; bits &= bits - 1) {
            const size_t n = b * kLanes + __builtin_ctz(bits);
            if (n != first && n < count && bounds[n] <= below) test(slots[n]);  // `below` may have shrunk since
          }
      }
      const double best = std::sqrt(o.distance);
      if (o.triangle != UINT32_MAX && !(best + vlen(vsub(p, c)) <= reach)) {
        // Not certified: every triangle nearer than the best so far is in a cluster within that distance of p
        // (a gather of the cluster scene: the triangle scene is cold here).
        gather(p, best, own, false);
        for (uint32_t k : own.clusters)
          for (size_t b = set->first[k]; b < set->first[k + 1]; ++b) {
            const Lanes bound = blockBounds2(reinterpret_cast<const Lanes*>(&set->rows[b * 16 * kLanes]),
                                             Lanes{} + pf[0], Lanes{} + pf[1], Lanes{} + pf[2]);
            for (unsigned bits = lanesAtMost(bound, Lanes{} + below); bits; bits &= bits - 1)
              test(b * kLanes + __builtin_ctz(bits));
          }
        o.distance_squared = o.distance;
        o.distance = std::sqrt(o.distance);
      } else {
        o.distance_squared = o.distance;
        o.distance = best;
      }
      if (o.triangle == UINT32_MAX) o = closest(p, hint);
      farthest = std::max(farthest, o.distance);
      hint = o.triangle;
    }
    extra = std::clamp(1.25 * farthest, kReachMin * m.mean_radius, kReachMax * m.mean_radius);
  }
}

}  // namespace scanpress
