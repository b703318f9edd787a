#include "spatial/surface_index.h"

#include <embree3/rtcore.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <mutex>
#include <vector>
#if defined(__SSE__)
#include <xmmintrin.h>
#endif

#include "engine/geometry.h"

namespace scanpress {

struct EmbreeDevice::ErrorSlot {
  std::mutex mutex;
  std::string message;
};

namespace {

void onEmbreeError(void* user, RTCError code, const char* str) {
  auto* slot = static_cast<EmbreeDevice::ErrorSlot*>(user);
  std::lock_guard<std::mutex> lock(slot->mutex);
  slot->message = "Embree error " + std::to_string(static_cast<int>(code)) + ": " + (str ? str : "");
}

}  // namespace

Result<std::shared_ptr<EmbreeDevice>> EmbreeDevice::create() {
  std::shared_ptr<EmbreeDevice> d(new EmbreeDevice());
  d->error_ = std::make_unique<ErrorSlot>();
  RTCDevice device = rtcNewDevice(nullptr);
  if (!device)
    return makeError(ErrorCode::kIo, "cannot create an Embree device (error " +
                                         std::to_string(static_cast<int>(rtcGetDeviceError(nullptr))) + ")");
  rtcSetDeviceErrorFunction(device, onEmbreeError, d->error_.get());
  d->device_ = device;
  return d;
}

EmbreeDevice::~EmbreeDevice() {
  if (device_) rtcReleaseDevice(static_cast<RTCDevice>(device_));
}

std::string EmbreeDevice::lastError() const {
  std::lock_guard<std::mutex> lock(error_->mutex);
  return error_->message;
}

namespace {

constexpr size_t kLanes = 4;  // one SSE register; GCC's vector extension keeps this portable
typedef float Lanes __attribute__((vector_size(4 * kLanes), aligned(4)));

// closestMany's view of the triangles: clusters of at most kClusterSize nearby triangles (median splits), each a
// primitive of a second Embree scene (user geometry, its box as bounds), so that one gather returns a few
// clusters instead of tens of triangles. A cluster's triangles sit together:
// their plane records (plane and edge lines in float, for lower bounds) transposed in blocks of kLanes, their ids
// and their corners in double (for exact tests).
struct ClusterSet {
  RTCScene scene = nullptr;
  std::vector<float> boxes;     // per cluster: lower xyz, 0, upper xyz, 0 (relative to the origin, rounded outward);
                                // for Embree's build, then freed
  std::vector<uint32_t> first;  // cluster k's blocks are [first[k], first[k + 1])
  std::vector<float> rows;      // per block: 16 rows of kLanes floats (row r = component r of the records)
  std::vector<uint32_t> ids;    // per slot (block * kLanes + lane): the triangle, UINT32_MAX in an unused lane
  std::vector<Vec3d> corners;   // per slot: three corners in double
  ~ClusterSet() {
    if (scene) rtcReleaseScene(scene);
  }
};

}  // namespace

struct SurfaceIndex::Impl {
  std::shared_ptr<EmbreeDevice> device;
  RTCScene scene = nullptr;
  std::span<const Vec3d> positions;
  std::span<const Triangle> triangles;
  std::vector<float> vertices;  // float xyz relative to origin, padded for Embree's 16-byte loads
  std::vector<float> spheres;   // per triangle: bounding-sphere center (relative to origin) and radius
  Vec3d origin{0, 0, 0};
  float slack = 0;  // absolute float rounding of the vertices: added to every search radius
  // closestMany's clusters (see ClusterSet below), built on its first batch.
  std::unique_ptr<ClusterSet> clusters;
  std::once_flag clusters_built;
  double mean_radius = 0;  // of the triangles' bounding spheres (sizes closestMany's runs)
  ~Impl() {
    if (scene) rtcReleaseScene(scene);
  }
};

namespace {

// Triangles that may share a cluster: at most kClusterSize, within a box of half-diagonal kClusterRadii mean
// radii. Two blocks of kLanes; 4 radii keeps big triangles apart and was as fast as 3 coming back from igea's
// 10% simplification, 3% faster going out (8 A/B rounds; 3.5 and 6 within noise).
constexpr size_t kClusterSize = 8;
constexpr double kClusterRadii = 4.0;

// The bits of v (21 of them) two apart: one axis of a 63-bit Morton key.
uint64_t spreadBits(uint64_t v) {
  v &= 0x1fffff;
  v = (v | v << 32) & 0x1f00000000ffffULL;
  v = (v | v << 16) & 0x1f0000ff0000ffULL;
  v = (v | v << 8) & 0x100f00f00f00f00fULL;
  v = (v | v << 4) & 0x10c30c30c30c30c3ULL;
  v = (v | v << 2) & 0x1249249249249249ULL;
  return v;
}

// The points in Morton order of their cells, the points not finite last, ties in index order, as one word each:
// the cell's Morton key, then the point's index in the lowest `index_bits` bits; bit 63 set for a point not
// finite. Cells are cubes of size 1 / inv_cell from the finite points' lower corner, larger if the batch spans more
// than the 2^b cells per axis that fit (b = (63 - index_bits) / 3, at most 21). A stable radix sort of these words
// on the bytes where they differ: a batch of nearby points shares most of its keys' bits. (Pairs of key and index
// sorted after a partition of the points not finite took twice as long.)
void mortonOrder(std::span<const Vec3d> points, double inv_cell, int index_bits, std::vector<uint64_t>& order,
                 std::vector<uint64_t>& scratch) {
  const size_t n = points.size();
  order.resize(n);
  scratch.resize(n);
  auto finite = [](const Vec3d& p) { return std::isfinite(p[0]) && std::isfinite(p[1]) && std::isfinite(p[2]); };
  Vec3d lo, hi;
  for (int a = 0; a < 3; ++a) lo[a] = std::numeric_limits<double>::infinity(), hi[a] = -lo[a];
  for (const Vec3d& p : points)
    if (finite(p))
      for (int a = 0; a < 3; ++a) lo[a] = std::min(lo[a], p[a]), hi[a] = std::max(hi[a], p[a]);
  const int bits = std::min(21, (63 - index_bits) / 3);
  const double top = double((1 << bits) - 1);
  double scale = inv_cell;
  for (int a = 0; a < 3; ++a)
    if ((hi[a] - lo[a]) * scale > top) scale = top / (hi[a] - lo[a]);
  for (size_t i = 0; i < n; ++i) {
    const Vec3d& p = points[i];
    if (!finite(p)) {
      order[i] = uint64_t(1) << 63 | i;
      continue;
    }
    uint64_t key = 0;
    for (int a = 0; a < 3; ++a) {  // NaN (an infinite span times a zero scale) counts as 0; the conversion floors
      const double g = (p[a] - lo[a]) * scale;
      key |= spreadBits(uint64_t(g > 0 ? std::min(g, top) : 0.0)) << (2 - a);
    }
    order[i] = key << index_bits | i;
  }
  uint64_t vary = 0;
  for (size_t i = 1; i < n; ++i) vary |= order[i] ^ order[0];
  uint64_t* from = order.data();
  uint64_t* to = scratch.data();
  for (int shift = index_bits; shift < 64; shift += 8) {
    if (((vary >> shift) & 0xff) == 0) continue;  // the same byte in every word
    uint32_t start[257] = {};
    for (size_t k = 0; k < n; ++k) ++start[((from[k] >> shift) & 0xff) + 1];
    for (size_t d = 1; d < 257; ++d) start[d] += start[d - 1];
    for (size_t k = 0; k < n; ++k) to[start[(from[k] >> shift) & 0xff]++] = from[k];
    std::swap(from, to);
  }
  if (from != order.data()) order.swap(scratch);
}

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

// Grows the box [lo, hi] to take in [add_lo, add_hi] if the result's half-diagonal stays within `half`; false
// (box unchanged) otherwise.
bool growWithin(Vec3d& lo, Vec3d& hi, const Vec3d& add_lo, const Vec3d& add_hi, double half) {
  Vec3d l2, h2;
  for (int a = 0; a < 3; ++a) l2[a] = std::min(lo[a], add_lo[a]), h2[a] = std::max(hi[a], add_hi[a]);
  const Vec3d d = vsub(h2, l2);
  if (!(0.25 * vdot(d, d) <= half * half)) return false;
  lo = l2, hi = h2;
  return true;
}

// Lane `at` of blocks of plane records (16 rows of kLanes floats): the record's component r is result[r * kLanes].
template <typename Float>
Float* laneOf(Float* rows, size_t at) {
  return rows + (at / kLanes) * 16 * kLanes + at % kLanes;
}

// Copies the record of lane `from` into lane `to`, or, without `from`, makes `to` unused: plane offset -inf, a
// bound of +inf (its triangle is never tested).
void setLane(float* to, const float* from) {
  for (size_t a = 0; a < 16; ++a)
    to[a * kLanes] = from ? from[a * kLanes] : a == 3 ? -std::numeric_limits<float>::infinity() : 0.f;
}

void clusterBounds(const RTCBoundsFunctionArguments* args) {
  const float* b = &static_cast<const ClusterSet*>(args->geometryUserPtr)->boxes[8 * size_t(args->primID)];
  args->bounds_o->lower_x = b[0], args->bounds_o->lower_y = b[1], args->bounds_o->lower_z = b[2];
  args->bounds_o->upper_x = b[4], args->bounds_o->upper_y = b[5], args->bounds_o->upper_z = b[6];
}

// closestMany's clusters and their Embree scene, built on its first use (closest() and intersect() do without).
// Triangles with a corner not finite are left out: their distance is never the least. Null if Embree fails.
std::unique_ptr<ClusterSet> buildClusters(const SurfaceIndex::Impl& m, RTCDevice device) {
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
  // kClusterRadii mean radii (or a single triangle). The clusters come out in the splits' (spatial) order. On
  // igea, 7.98 triangles per cluster within 2.5 radii; Morton order cut greedily gave 6.1 within 2.45.
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
  const size_t clusters = set->first.size() - 1;
  set->scene = rtcNewScene(device);
  rtcSetSceneBuildQuality(set->scene, RTC_BUILD_QUALITY_HIGH);
  if (clusters > 0) {
    RTCGeometry geom = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_USER);
    rtcSetGeometryUserPrimitiveCount(geom, unsigned(clusters));
    rtcSetGeometryUserData(geom, set.get());
    rtcSetGeometryBoundsFunction(geom, clusterBounds, nullptr);
    rtcCommitGeometry(geom);
    rtcAttachGeometry(set->scene, geom);
    rtcReleaseGeometry(geom);
  }
  rtcCommitScene(set->scene);
  if (rtcGetDeviceError(device) != RTC_ERROR_NONE) return nullptr;
  std::vector<float>().swap(set->boxes);  // read by Embree's build only (the scene is never committed again)
  return set;
}

}  // namespace

SurfaceIndex::SurfaceIndex(SurfaceIndex&&) noexcept = default;
SurfaceIndex& SurfaceIndex::operator=(SurfaceIndex&&) noexcept = default;
SurfaceIndex::~SurfaceIndex() = default;

size_t SurfaceIndex::triangleCount() const { return impl_->triangles.size(); }

Result<SurfaceIndex> SurfaceIndex::build(std::shared_ptr<EmbreeDevice> device, std::span<const Vec3d> positions,
                                         std::span<const Triangle> triangles) {
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

  RTCDevice dev = static_cast<RTCDevice>(m.device->handle());
  m.scene = rtcNewScene(dev);
  rtcSetSceneFlags(m.scene, RTC_SCENE_FLAG_ROBUST);
  rtcSetSceneBuildQuality(m.scene, RTC_BUILD_QUALITY_MEDIUM);
  if (!triangles.empty()) {
    RTCGeometry geom = rtcNewGeometry(dev, RTC_GEOMETRY_TYPE_TRIANGLE);
    rtcSetSharedGeometryBuffer(geom, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, m.vertices.data(), 0,
                               3 * sizeof(float), positions.size());
    // Triangle is std::array<uint32_t, 3>: tightly packed, shared with Embree as it is.
    static_assert(sizeof(Triangle) == 3 * sizeof(uint32_t));
    rtcSetSharedGeometryBuffer(geom, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, triangles.data(), 0,
                               sizeof(Triangle), triangles.size());
    rtcCommitGeometry(geom);
    rtcAttachGeometry(m.scene, geom);
    rtcReleaseGeometry(geom);
  }
  rtcCommitScene(m.scene);
  if (rtcGetDeviceError(dev) != RTC_ERROR_NONE)
    return makeError(ErrorCode::kInternal, "building the Embree scene failed: " + m.device->lastError());
  return index;
}

namespace {

struct ClosestQuery {
  const SurfaceIndex::Impl* impl;
  Vec3d p;
  double best_d2;
  Vec3d best;
  uint32_t triangle;
  float px, py, pz;  // p relative to the origin, in float
  float best_f;      // conservative (rounded up) float bound of the best distance
};

}  // namespace

static bool closestCallback(RTCPointQueryFunctionArguments* args) {
  auto* q = static_cast<ClosestQuery*>(args->userPtr);
  const auto& impl = *q->impl;
  // Reject by bounding sphere: |p - c| - r > best means no point of the triangle can be closer.
  const float* sp = &impl.spheres[4 * size_t(args->primID)];
  const float dx = q->px - sp[0], dy = q->py - sp[1], dz = q->pz - sp[2];
  const float reach = q->best_f + sp[3];
  if (dx * dx + dy * dy + dz * dz > reach * reach * (1.0f + 8 * std::numeric_limits<float>::epsilon())) return false;
  const Triangle& t = impl.triangles[args->primID];
  const Vec3d c = closestPointOnTriangle(q->p, impl.positions[t[0]], impl.positions[t[1]], impl.positions[t[2]]);
  const Vec3d d = vsub(c, q->p);
  const double d2 = vdot(d, d);
  if (d2 >= q->best_d2) return false;
  q->best_d2 = d2;
  q->best = c;
  q->triangle = args->primID;
  // Shrink Embree's (float) radius, never below the exact distance plus the vertices' float rounding.
  const float r = static_cast<float>(std::sqrt(d2)) * (1.0f + 4 * std::numeric_limits<float>::epsilon()) + impl.slack;
  q->best_f = r;
  if (r < args->query->radius) {
    args->query->radius = r;
    return true;
  }
  return false;
}

SurfaceIndex::Closest SurfaceIndex::closest(const Vec3d& p, uint32_t hint) const {
  Closest out;
  if (impl_->triangles.empty()) {
    out.distance = std::numeric_limits<double>::infinity();
    return out;
  }
  ClosestQuery q{impl_.get(), p, std::numeric_limits<double>::infinity(), p, UINT32_MAX, 0, 0, 0,
                 std::numeric_limits<float>::infinity()};
  RTCPointQuery query;
  query.x = q.px = static_cast<float>(p[0] - impl_->origin[0]);
  query.y = q.py = static_cast<float>(p[1] - impl_->origin[1]);
  query.z = q.pz = static_cast<float>(p[2] - impl_->origin[2]);
  query.time = 0.f;
  query.radius = std::numeric_limits<float>::infinity();
  if (hint < impl_->triangles.size()) {
    const Triangle& t = impl_->triangles[hint];
    const Vec3d c = closestPointOnTriangle(p, impl_->positions[t[0]], impl_->positions[t[1]], impl_->positions[t[2]]);
    const Vec3d d = vsub(c, p);
    const double d2 = vdot(d, d);
    if (!std::isnan(d2)) {  // NaN when p is not finite: then ignored, the answer is the same as without a hint
      q.best_d2 = d2;
      q.best = c;
      q.triangle = hint;
      query.radius = q.best_f =
          static_cast<float>(std::sqrt(d2)) * (1.0f + 4 * std::numeric_limits<float>::epsilon()) + impl_->slack;
    }
  }
  RTCPointQueryContext context;
  rtcInitPointQueryContext(&context);
  rtcPointQuery(impl_->scene, &query, &context, closestCallback, &q);
  out.distance = std::sqrt(q.best_d2);
  out.point = q.best;
  out.triangle = q.triangle;
  return out;
}

namespace {

constexpr float kEps = std::numeric_limits<float>::epsilon();
static_assert(kClusterSize % kLanes == 0);

// Squared lower bounds of the distance from p = (x, y, z) (relative to the origin) to the kLanes triangles of one
// block of plane records: the distance to the plane and, within the plane, beyond the farthest of the edge lines.
inline Lanes blockBounds2(const Lanes* r, Lanes x, Lanes y, Lanes z) {
  const Lanes h = r[0] * x + r[1] * y + r[2] * z - r[3];
  const Lanes e0 = r[4] * x + r[5] * y + r[6] * z - r[7];
  const Lanes e1 = r[8] * x + r[9] * y + r[10] * z - r[11];
  const Lanes e2 = r[12] * x + r[13] * y + r[14] * z - r[15];
  Lanes e = e0 > e1 ? e0 : e1;
  e = e > e2 ? e : e2;
  e = e > Lanes{} ? e : Lanes{};
  return h * h + e * e;
}
// blockBounds2 for `blocks` blocks.
void lowerBounds2(const float* rows, size_t blocks, const float* p, float* __restrict out) {
  const Lanes* r = reinterpret_cast<const Lanes*>(rows);
  const Lanes x = Lanes{} + p[0], y = Lanes{} + p[1], z = Lanes{} + p[2];
  for (size_t b = 0; b < blocks; ++b, r += 16, out += kLanes)
    *reinterpret_cast<Lanes*>(out) = blockBounds2(r, x, y, z);
}

typedef int LaneInts __attribute__((vector_size(4 * kLanes), aligned(4)));

// Bit l set where a[l] <= b[l]: one movmskps on x86 (GCC does not find it in the portable loop, which took ~10
// instructions).
inline unsigned lanesAtMost(Lanes a, Lanes b) {
  const LaneInts m = a <= b;
#if defined(__SSE__)
  return unsigned(_mm_movemask_ps(reinterpret_cast<__m128>(m)));
#else
  unsigned bits = 0;
  for (size_t l = 0; l < kLanes; ++l) bits |= unsigned(m[l] & 1) << l;
  return bits;
#endif
}

// The bounds of the `count` blocks of plane records at rows[0], rows[1], ... (at least one), and the index of the
// least bound (the first of equals), in one pass.
size_t boundsAndLeast(const float* const* rows, size_t count, const float* p, float* __restrict out) {
  const Lanes x = Lanes{} + p[0], y = Lanes{} + p[1], z = Lanes{} + p[2];
  Lanes* v = reinterpret_cast<Lanes*>(out);
  Lanes low = v[0] = blockBounds2(reinterpret_cast<const Lanes*>(rows[0]), x, y, z);
  for (size_t b = 1; b < count; ++b) {
    v[b] = blockBounds2(reinterpret_cast<const Lanes*>(rows[b]), x, y, z);
    low = v[b] < low ? v[b] : low;
  }
  float least = low[0];
  for (size_t l = 1; l < kLanes; ++l) least = low[l] < least ? low[l] : least;
  for (size_t b = 0; b < count; ++b)
    if (const unsigned bits = lanesAtMost(v[b], Lanes{} + least)) return b * kLanes + __builtin_ctz(bits);
  return 0;  // NaN bounds only
}

// Embree's gather: every cluster whose box the query sphere reaches.
struct Gather {
  const ClusterSet* set;
  std::vector<uint32_t>* clusters;
  bool corners;  // prefetch the clusters' corners too (a run that bounds its clusters in place)
};

bool gatherCallback(RTCPointQueryFunctionArguments* args) {
  auto* g = static_cast<Gather*>(args->userPtr);
  const ClusterSet& set = *g->set;
  const size_t k = args->primID;
  g->clusters->push_back(uint32_t(k));
  // The cluster's plane records, ids and corners, to L2, while Embree goes on.
  const size_t b0 = set.first[k], b1 = set.first[k + 1];
  auto prefetch = [](const void* from, size_t bytes) {
    for (size_t off = 0; off < bytes; off += 64) __builtin_prefetch(static_cast<const char*>(from) + off, 0, 2);
  };
  prefetch(&set.rows[b0 * 16 * kLanes], (b1 - b0) * 16 * kLanes * sizeof(float));
  if (g->corners) prefetch(&set.corners[b0 * kLanes * 3], (b1 - b0) * kLanes * 3 * sizeof(Vec3d));
  __builtin_prefetch(&set.ids[b0 * kLanes], 0, 2);
  return false;
}

// Points are ordered by the Morton key of their cell (kCellRadii mean triangle radii); runs are maximal stretches
// of that order whose box has a half-diagonal of at most kRunRadii. The gather reaches beyond the run's points by
// at least kReachMin radii, or by 1.25 times the largest distance in the last run done (the gathers are one run
// ahead: that is the run before the previous), at most kReachMax. With the median-split clusters, runs of 1.5
// radii beat 2 by median in four sweeps of 5-10 rounds (by 5-20%) on igea against its 10% simplification and were
// as fast the other way; 1, 1.25, 2.5 and 3 were not faster, nor was a cap of 8 or 12 points per run.
constexpr double kCellRadii = 1.0, kRunRadii = 1.5, kReachMin = 0.1, kReachMax = 2.0;
// A run of at most kDirectPoints points bounds its clusters' blocks where they are (its gather prefetches their
// corners too); a larger run first copies out the triangles that may lie within its reach, so that each of its
// points bounds fewer. Against copying out for every run (7 A/B rounds, median): 8 points was 11% faster coming
// back from igea's 10% simplification (3.5 points per run) and as fast going out (13.7 points per run); 4, 6 and 11
// were not better; bounding in place for every run was 17% slower going out.
constexpr size_t kDirectPoints = 8;

}  // namespace

void SurfaceIndex::closestMany(std::span<const Vec3d> points, std::span<Closest> out) const {
  const Impl& m = *impl_;
  if (!m.triangles.empty() && points.size() >= 2)
    std::call_once(impl_->clusters_built, [this] {
      impl_->clusters = buildClusters(*impl_, static_cast<RTCDevice>(impl_->device->handle()));
    });
  const ClusterSet* set = m.clusters.get();
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
    Gather callback{set, &g.clusters, corners};
    RTCPointQuery query;
    query.x = g.cf[0], query.y = g.cf[1], query.z = g.cf[2], query.time = 0.f, query.radius = g.reach_f;
    RTCPointQueryContext context;
    rtcInitPointQueryContext(&context);
    rtcPointQuery(set->scene, &query, &context, gatherCallback, &callback);
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
    // first `count` lanes). A small run takes its clusters' blocks (unused lanes are never nearest). A larger run
    // copies out the triangles that may lie within R of c (by their bound).
    size_t gathered = 0;  // lanes of the run's clusters: room for every candidate
    for (uint32_t k : current.clusters) gathered += (set->first[k + 1] - set->first[k]) * kLanes;
    if (slots.size() < gathered) slots.resize(gathered), rows.resize(gathered * 16), bounds.resize(gathered);
    blocks.clear();
    size_t count = 0;
    if (inPlace(runs[r])) {
      for (uint32_t k : current.clusters)
        for (size_t b = set->first[k]; b < set->first[k + 1]; ++b) {
          blocks.push_back(&set->rows[b * 16 * kLanes]);
          for (size_t l = 0; l < kLanes; ++l) slots[count++] = uint32_t(b * kLanes + l);
        }
    } else {
      const float within = current.reach_f * current.reach_f * (1 + 16 * kEps);
      for (uint32_t k : current.clusters) {
        const size_t b0 = set->first[k], b1 = set->first[k + 1];
        Lanes near[kClusterSize / kLanes];
        lowerBounds2(&set->rows[b0 * 16 * kLanes], b1 - b0, current.cf, reinterpret_cast<float*>(near));
        for (size_t b = b0; b < b1; ++b)
          for (unsigned bits = lanesAtMost(near[b - b0], Lanes{} + within); bits; bits &= bits - 1) {
            const size_t slot = b * kLanes + __builtin_ctz(bits);  // not an unused lane: its bound is infinite
            setLane(laneOf(rows.data(), count), laneOf(set->rows.data(), slot));
            slots[count++] = uint32_t(slot);
            const char* corners = reinterpret_cast<const char*>(&set->corners[3 * slot]);
            __builtin_prefetch(corners);
            __builtin_prefetch(corners + 3 * sizeof(Vec3d) - 1);
          }
      }
      for (size_t lanes = count; lanes % kLanes; ++lanes) setLane(laneOf(rows.data(), lanes), nullptr);  // the rest
      for (size_t b = 0; b * kLanes < count; ++b) blocks.push_back(&rows[b * 16 * kLanes]);
    }
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
        // Not certified: every triangle nearer than the best so far is in a cluster within that distance of p.
        // (A query of the triangle scene, which closestMany leaves cold, cost ~5,700 cycles here.)
        gather(p, best, own, false);
        for (uint32_t k : own.clusters)
          for (size_t b = set->first[k]; b < set->first[k + 1]; ++b) {
            const Lanes bound = blockBounds2(reinterpret_cast<const Lanes*>(&set->rows[b * 16 * kLanes]),
                                             Lanes{} + pf[0], Lanes{} + pf[1], Lanes{} + pf[2]);
            for (unsigned bits = lanesAtMost(bound, Lanes{} + below); bits; bits &= bits - 1)
              test(b * kLanes + __builtin_ctz(bits));
          }
        o.distance = std::sqrt(o.distance);
      } else {
        o.distance = best;
      }
      if (o.triangle == UINT32_MAX) o = closest(p, hint);
      farthest = std::max(farthest, o.distance);
      hint = o.triangle;
    }
    extra = std::clamp(1.25 * farthest, kReachMin * m.mean_radius, kReachMax * m.mean_radius);
  }
}

SurfaceIndex::Hit SurfaceIndex::intersect(const Vec3d& origin, const Vec3d& dir) const {
  Hit out;
  if (impl_->triangles.empty()) return out;
  RTCRayHit rh;
  rh.ray.org_x = static_cast<float>(origin[0] - impl_->origin[0]);
  rh.ray.org_y = static_cast<float>(origin[1] - impl_->origin[1]);
  rh.ray.org_z = static_cast<float>(origin[2] - impl_->origin[2]);
  rh.ray.dir_x = static_cast<float>(dir[0]);
  rh.ray.dir_y = static_cast<float>(dir[1]);
  rh.ray.dir_z = static_cast<float>(dir[2]);
  rh.ray.tnear = 0.f;
  rh.ray.tfar = std::numeric_limits<float>::infinity();
  rh.ray.time = 0.f;
  rh.ray.mask = 0xFFFFFFFFu;
  rh.ray.id = 0;
  rh.ray.flags = 0;
  rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
  rh.hit.primID = RTC_INVALID_GEOMETRY_ID;
  rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
  RTCIntersectContext context;
  rtcInitIntersectContext(&context);
  rtcIntersect1(impl_->scene, &context, &rh);
  if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) return out;
  out.hit = true;
  out.t = rh.ray.tfar;
  out.triangle = rh.hit.primID;
  Vec3d n{rh.hit.Ng_x, rh.hit.Ng_y, rh.hit.Ng_z};
  const double len = vlen(n);
  n = len > 0 ? vmul(n, 1.0 / len) : Vec3d{0, 0, 1};
  if (vdot(n, dir) > 0) n = vmul(n, -1.0);
  out.normal = n;
  return out;
}

}  // namespace scanpress
