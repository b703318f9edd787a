// closestMany's clusters: median splits of the triangles, their plane records, corners and ids in blocks of
// kLanes (surface_index_internal.h); their Embree scene is built by surface_embree.cpp.
#include "spatial/surface_clusters.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <utility>

#include "engine/geometry.h"
#include "spatial/surface_index_internal.h"

namespace scanpress::surface {

namespace {

// Triangles that may share a cluster: at most kClusterSize, within a box of half-diagonal kClusterRadii mean
// radii, which keeps big triangles apart (the value: bench/RESULTS.md).
constexpr double kClusterRadii = 4.0;

// The plane record of a triangle (corners relative to the origin): unit normal and offset, then each edge's
// outward in-plane unit normal and offset. All zeros (a bound of 0, never rejected) for a degenerate or
// needle-thin triangle (sine of its angle below 1e-6), whose normal's direction is too imprecise.
void planeRecord(const Vec3d v[3], float out[16]) {
  std::fill_n(out, 16, 0.f);
  const Vec3d e1 = vsub(v[1], v[0]), e2 = vsub(v[2], v[0]);
  Vec3d n = vcross(e1, e2);
  const double len = vlen(n);
  if (!(len > 1e-6 * vlen(e1) * vlen(e2))) return;
  n = vmul(n, 1.0 / len);
  for (int a = 0; a < 3; ++a) out[a] = static_cast<float>(n[a]);
  out[3] = static_cast<float>(vdot(n, v[0]));
  for (int e = 0; e < 3; ++e) {
    const Vec3d& a = v[e];
    const Vec3d& b = v[(e + 1) % 3];
    Vec3d mo = vcross(vsub(b, a), n);  // in the plane, perpendicular to the edge, away from the third vertex
    const double ml = vlen(mo);
    if (!(ml > 0)) continue;
    mo = vmul(mo, 1.0 / ml);
    for (int k = 0; k < 3; ++k) out[4 + 4 * e + k] = static_cast<float>(mo[k]);
    out[4 + 4 * e + 3] = static_cast<float>(vdot(mo, a));
  }
}

float roundDown(double x) {
  float f = static_cast<float>(x);
  return f > x ? std::nextafter(f, -std::numeric_limits<float>::infinity()) : f;
}
float roundUp(double x) {
  float f = static_cast<float>(x);
  return f < x ? std::nextafter(f, std::numeric_limits<float>::infinity()) : f;
}

}  // namespace

std::unique_ptr<ClusterSet> buildClusters(const SurfaceIndex::Impl& m) {
  auto set = std::make_unique<ClusterSet>();
  // The box of triangle t relative to the origin; false if a corner is not finite.
  auto triangleBox = [&m](uint32_t t, Vec3d& lo, Vec3d& hi) {
    bool finite = true;
    for (int a = 0; a < 3; ++a) {
      lo[a] = std::numeric_limits<double>::infinity(), hi[a] = -lo[a];
      for (uint32_t v : m.triangles[t]) {
        const double x = m.positions[v][a] - m.origin[a];
        finite = finite && std::isfinite(x);
        lo[a] = std::min(lo[a], x), hi[a] = std::max(hi[a], x);
      }
    }
    return finite;
  };
  struct Item {
    float c[3];  // the triangle's box center, doubled (the triangle's place in the splits)
    uint32_t t;
  };
  std::vector<Item> items;
  items.reserve(m.triangles.size());
  for (size_t t = 0; t < m.triangles.size(); ++t) {
    Vec3d lo, hi;
    Item it{{}, uint32_t(t)};
    bool finite = triangleBox(uint32_t(t), lo, hi);
    for (int a = 0; a < 3; ++a) {
      it.c[a] = static_cast<float>(lo[a] + hi[a]);
      finite = finite && std::isfinite(it.c[a]);
    }
    if (finite) items.push_back(it);
  }
  // Clusters by median splits along the longest axis of the centers' box, at multiples of kClusterSize (so that
  // nearly every cluster is full), until a part has at most kClusterSize triangles within a box of half-diagonal
  // kClusterRadii mean radii (or a single triangle). The clusters come out in the splits' (spatial) order.
  const double limit = kClusterRadii * m.mean_radius;
  std::vector<std::pair<uint32_t, uint32_t>> parts;  // item ranges, one per cluster (its box into set->boxes)
  std::vector<std::pair<uint32_t, uint32_t>> todo{{0u, uint32_t(items.size())}};
  size_t blocks = 0;
  while (!todo.empty()) {
    const auto [b, e] = todo.back();
    todo.pop_back();
    const size_t n = e - b;
    if (n == 0) continue;
    if (n <= kClusterSize) {  // one cluster if its box is small enough
      Vec3d lo, hi, tlo, thi;
      triangleBox(items[b].t, lo, hi);
      bool small = true;
      for (uint32_t k = b + 1; k < e && small; ++k) {
        triangleBox(items[k].t, tlo, thi);
        small = growWithin(lo, hi, tlo, thi, limit);
      }
      if (n == 1 || small) {
        parts.push_back({b, e});
        blocks += (n + kLanes - 1) / kLanes;
        for (int a = 0; a < 3; ++a) set->boxes.push_back(roundDown(lo[a]));
        set->boxes.push_back(0.f);
        for (int a = 0; a < 3; ++a) set->boxes.push_back(roundUp(hi[a]));
        set->boxes.push_back(0.f);
        continue;
      }
    }
    float lo[3], hi[3];
    for (int a = 0; a < 3; ++a) lo[a] = std::numeric_limits<float>::infinity(), hi[a] = -lo[a];
    for (uint32_t k = b; k < e; ++k)
      for (int a = 0; a < 3; ++a) lo[a] = std::min(lo[a], items[k].c[a]), hi[a] = std::max(hi[a], items[k].c[a]);
    int axis = 0;
    for (int a = 1; a < 3; ++a)
      if (hi[a] - lo[a] > hi[axis] - lo[axis]) axis = a;
    const size_t half = n > kClusterSize ? kClusterSize * ((n + 2 * kClusterSize - 1) / (2 * kClusterSize))
                                         : n > kLanes ? kLanes : n / 2;
    std::nth_element(items.begin() + b, items.begin() + b + half, items.begin() + e,
                     [axis](const Item& x, const Item& y) { return x.c[axis] < y.c[axis]; });
    todo.push_back({uint32_t(b + half), e});  // the lower half first
    todo.push_back({b, uint32_t(b + half)});
  }
  set->ids.assign(blocks * kLanes, UINT32_MAX);
  set->corners.resize(blocks * kLanes * 3);
  set->rows.resize(blocks * 16 * kLanes);
  set->first.reserve(parts.size() + 1);
  set->first.push_back(0);
  size_t block = 0;
  for (const auto& [b, e] : parts) {
    for (uint32_t k = b; k < e; ++k) {
      const uint32_t t = items[k].t;
      const size_t slot = block * kLanes + (k - b);
      Vec3d v[3];
      for (int c = 0; c < 3; ++c) v[c] = vsub(m.positions[m.triangles[t][c]], m.origin);
      float record[16];
      planeRecord(v, record);
      float* dst = laneOf(set->rows.data(), slot);
      for (size_t a = 0; a < 16; ++a) dst[a * kLanes] = record[a];
      set->ids[slot] = t;
      for (int c = 0; c < 3; ++c) set->corners[3 * slot + c] = m.positions[m.triangles[t][c]];
    }
    const size_t end = block + (e - b + kLanes - 1) / kLanes;
    for (size_t slot = block * kLanes + (e - b); slot < end * kLanes; ++slot)  // the last block's rest
      setLane(laneOf(set->rows.data(), slot), nullptr);
    block = end;
    set->first.push_back(uint32_t(block));
  }
  set->scene = clusterScene(*m.device, *set);
  if (!set->scene.handle()) return nullptr;
  std::vector<float>().swap(set->boxes);  // read by Embree's build only (the scene is never committed again)
  return set;
}

}  // namespace scanpress::surface
