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

// The plane record of a triangle with corners w (absolute; the record is relative to `origin`): unit normal
// and offset, then each edge's outward in-plane unit normal and offset. Directions come from differences of
// the absolute corners (exact but for one rounding, even for corners a few ulps apart), offsets from the
// corners relative to the origin. A triangle with coincident corners is its segment or point: its record
// bounds the distance to that (segmentRecord). All zeros (a bound of 0, never rejected) for any other
// degenerate or needle-thin triangle (sine of its angle at w[0] below 1e-6), whose normal's direction is too
// imprecise.
void segmentRecord(const Vec3d& a, const Vec3d& b, const Vec3d& origin, float out[16]);

void planeRecord(const Vec3d w[3], const Vec3d& origin, float out[16]) {
  std::fill_n(out, 16, 0.f);
  if (w[0] == w[1] || w[1] == w[2] || w[2] == w[0])
    return segmentRecord(w[0], w[0] == w[1] ? w[2] : w[1], origin, out);
  const Vec3d e1 = vsub(w[1], w[0]), e2 = vsub(w[2], w[0]);
  Vec3d n = vcross(e1, e2);
  const double len = vlen(n);
  if (!(len > 1e-6 * vlen(e1) * vlen(e2))) return;
  n = vmul(n, 1.0 / len);
  for (int a = 0; a < 3; ++a) out[a] = static_cast<float>(n[a]);
  out[3] = static_cast<float>(vdot(n, vsub(w[0], origin)));
  for (int e = 0; e < 3; ++e) {
    const Vec3d& a = w[e];
    const Vec3d& b = w[(e + 1) % 3];
    Vec3d mo = vcross(vsub(b, a), n);  // in the plane, perpendicular to the edge, away from the third vertex
    const double ml = vlen(mo);
    if (!(ml > 0)) continue;
    mo = vmul(mo, 1.0 / ml);
    for (int k = 0; k < 3; ++k) out[4 + 4 * e + k] = static_cast<float>(mo[k]);
    out[4 + 4 * e + 3] = static_cast<float>(vdot(mo, vsub(a, origin)));
  }
}

// The record of segment ab (a point if a == b), in the plane record's form: a unit n perpendicular to the
// segment as the "plane" (|n.(x - a)| is the distance along n), and its direction m as two "edges" (m.(x - b)
// beyond b, m.(a - x) behind a): the squared distance to the segment is at least the sum of the squares of
// those, as n and m are orthonormal.
void segmentRecord(const Vec3d& a, const Vec3d& b, const Vec3d& origin, float out[16]) {
  Vec3d m = vsub(b, a);
  const double ml = vlen(m);
  m = ml > 0 ? vmul(m, 1.0 / ml) : Vec3d{1, 0, 0};
  // n: m crossed with the axis least along it, normalized.
  int least = 0;
  for (int k = 1; k < 3; ++k)
    if (std::fabs(m[k]) < std::fabs(m[least])) least = k;
  Vec3d axis{0, 0, 0};
  axis[least] = 1;
  Vec3d n = vcross(m, axis);
  n = vmul(n, 1.0 / vlen(n));
  const Vec3d ar = vsub(a, origin), br = vsub(b, origin);
  for (int k = 0; k < 3; ++k) {
    out[k] = static_cast<float>(n[k]);
    out[4 + k] = static_cast<float>(m[k]);
    out[8 + k] = static_cast<float>(-m[k]);
  }
  out[3] = static_cast<float>(vdot(n, ar));
  out[7] = static_cast<float>(vdot(m, br));
  out[11] = static_cast<float>(-vdot(m, ar));
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
                        : n > kLanes     ? kLanes
                                         : n / 2;
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
      Vec3d w[3];
      for (int c = 0; c < 3; ++c) w[c] = m.positions[m.triangles[t][c]];
      float record[16];
      planeRecord(w, m.origin, record);
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
