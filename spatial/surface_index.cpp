#include "spatial/surface_index.h"

#include <embree3/rtcore.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <mutex>
#include <vector>

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

struct SurfaceIndex::Impl {
  std::shared_ptr<EmbreeDevice> device;
  RTCScene scene = nullptr;
  std::span<const Vec3d> positions;
  std::span<const Triangle> triangles;
  std::vector<float> vertices;  // float xyz relative to origin, padded for Embree's 16-byte loads
  std::vector<float> spheres;   // per triangle: bounding-sphere center (relative to origin) and radius
  Vec3d origin{0, 0, 0};
  float slack = 0;  // absolute float rounding of the vertices: added to every search radius
  // Per triangle, its plane and its three edges' outward in-plane normals (unit vectors and offsets relative to
  // the origin, 16 floats, one cache line): a lower bound of a point's distance to the triangle in four dot
  // products (closestMany).
  std::vector<float> planes;
  // Per triangle, its three corners in double: closestMany's exact tests read one place instead of four.
  std::vector<Vec3d> corners;
  std::once_flag records;  // planes and corners are built on closestMany's first batch
  double mean_radius = 0;  // of the triangles' bounding spheres (sizes closestMany's runs)
  ~Impl() {
    if (scene) rtcReleaseScene(scene);
  }
};

namespace {

// closestMany's per-triangle records, built on its first use (closest() and intersect() do without them).
void buildRecords(SurfaceIndex::Impl& m) {
  m.corners.resize(m.triangles.size() * 3);
  for (size_t t = 0; t < m.triangles.size(); ++t)
    for (int k = 0; k < 3; ++k) m.corners[3 * t + k] = m.positions[m.triangles[t][k]];
  m.planes.assign(m.triangles.size() * 16, 0.f);
  for (size_t t = 0; t < m.triangles.size(); ++t) {
    const Triangle& tri = m.triangles[t];
    const Vec3d v[3] = {vsub(m.positions[tri[0]], m.origin), vsub(m.positions[tri[1]], m.origin),
                        vsub(m.positions[tri[2]], m.origin)};
    const Vec3d e1 = vsub(v[1], v[0]), e2 = vsub(v[2], v[0]);
    Vec3d n = vcross(e1, e2);
    const double len = vlen(n);
    // Degenerate or needle-thin (sine of the angle below 1e-6, where the normal's direction loses precision): all
    // zeros, a bound of 0, never rejected.
    if (!(len > 1e-6 * vlen(e1) * vlen(e2))) continue;
    n = vmul(n, 1.0 / len);
    float* out = &m.planes[16 * t];
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
constexpr size_t kLanes = 4;  // one SSE register; GCC's vector extension keeps this portable
typedef float Lanes __attribute__((vector_size(4 * kLanes), aligned(4)));

// The candidate triangles of a run of points: their plane records in blocks of kLanes (block b holds 16 rows of
// kLanes floats, row r = component r of the records); unused lanes of the last block bound to infinity.
struct Candidates {
  std::vector<float> rows;
  std::vector<uint32_t> ids;
  void clear() { rows.clear(), ids.clear(); }
  size_t blocks() const { return rows.size() / (16 * kLanes); }
  void add(const float* record, uint32_t id) {
    const size_t k = ids.size();
    if (k % kLanes == 0) {
      rows.resize(rows.size() + 16 * kLanes, 0.f);
      // Plane offset -inf: the plane distance, hence the bound, of an unused lane is +inf.
      std::fill_n(rows.end() - 13 * kLanes, kLanes, -std::numeric_limits<float>::infinity());
    }
    float* dst = rows.data() + (k / kLanes) * 16 * kLanes + k % kLanes;
    for (size_t a = 0; a < 16; ++a) dst[a * kLanes] = record[a];
    ids.push_back(id);
  }
};

// Squared lower bound of the distance from p (relative to the origin) to a triangle, from its record: the
// distance to its plane and, within the plane, beyond the farthest of its edge lines.
float lowerBound2(const float* r, const float* p) {
  const float h = r[0] * p[0] + r[1] * p[1] + r[2] * p[2] - r[3];
  const float e0 = r[4] * p[0] + r[5] * p[1] + r[6] * p[2] - r[7];
  const float e1 = r[8] * p[0] + r[9] * p[1] + r[10] * p[2] - r[11];
  const float e2 = r[12] * p[0] + r[13] * p[1] + r[14] * p[2] - r[15];
  const float e = std::max(0.f, std::max(e0, std::max(e1, e2)));
  return h * h + e * e;
}

// lowerBound2 for every candidate at once.
void lowerBounds2(const Candidates& c, const float* p, float* __restrict out) {
  const Lanes* r = reinterpret_cast<const Lanes*>(c.rows.data());
  const Lanes x = Lanes{} + p[0], y = Lanes{} + p[1], z = Lanes{} + p[2], zero = {};
  for (size_t b = 0, n = c.blocks(); b < n; ++b, r += 16, out += kLanes) {
    const Lanes h = r[0] * x + r[1] * y + r[2] * z - r[3];
    const Lanes e0 = r[4] * x + r[5] * y + r[6] * z - r[7];
    const Lanes e1 = r[8] * x + r[9] * y + r[10] * z - r[11];
    const Lanes e2 = r[12] * x + r[13] * y + r[14] * z - r[15];
    Lanes e = e0 > e1 ? e0 : e1;
    e = e > e2 ? e : e2;
    e = e > zero ? e : zero;
    *reinterpret_cast<Lanes*>(out) = h * h + e * e;
  }
}

// Index of the least of the first `count` values (padded to whole blocks with +inf).
size_t argminOf(const float* v, size_t count) {
  const Lanes* r = reinterpret_cast<const Lanes*>(v);
  Lanes low = r[0];
  for (size_t b = 1; b * kLanes < count; ++b) low = r[b] < low ? r[b] : low;
  float least = low[0];
  for (size_t l = 1; l < kLanes; ++l) least = low[l] < least ? low[l] : least;
  for (size_t n = 0; n < count; ++n)
    if (v[n] == least) return n;
  return 0;
}

// Embree's gather: every triangle in a leaf the query sphere reaches. The callback only notes it and asks for
// its record, so that the loads overlap the rest of the traversal; the records are tested afterwards.
struct Gather {
  const SurfaceIndex::Impl* impl;
  std::vector<uint32_t>* prims;
};

bool gatherCallback(RTCPointQueryFunctionArguments* args) {
  auto* g = static_cast<Gather*>(args->userPtr);
  __builtin_prefetch(&g->impl->planes[16 * size_t(args->primID)]);
  g->prims->push_back(args->primID);
  return false;
}

// Runs: a grid cell is twice the target's mean triangle radius (measured on igea and its 10% simplification,
// both ways: half or twice that size is slower). The gather reaches beyond the run's points by at least a tenth
// of that radius, or by 1.25 times the largest distance in the previous run, at most two radii.
constexpr double kCellRadii = 2.0, kReachMin = 0.1, kReachMax = 2.0;

}  // namespace

void SurfaceIndex::closestMany(std::span<const Vec3d> points, std::span<Closest> out) const {
  const Impl& m = *impl_;
  if (m.triangles.empty() || points.size() < 2) {
    for (size_t i = 0; i < points.size(); ++i) out[i] = closest(points[i]);
    return;
  }
  // Points in order of the grid cell they fall in; a cell's points make a run. Points outside the grid's range
  // share the last cell; non-finite points sort last and are queried alone.
  const double cell = kCellRadii * m.mean_radius;
  std::vector<std::pair<uint64_t, uint32_t>> order(points.size());
  for (size_t i = 0; i < points.size(); ++i) {
    uint64_t key = 0;  // 63 bits: UINT64_MAX is free for the non-finite points
    bool finite = true;
    for (int a = 0; a < 3; ++a) {
      const double g = std::floor((points[i][a] - m.origin[a]) / cell) + double(1 << 20);
      key = key << 21 | (g >= 0 ? uint64_t(std::min(g, double((1 << 21) - 1))) : 0);
      finite = finite && std::isfinite(g);
    }
    order[i] = {finite ? key : UINT64_MAX, uint32_t(i)};
  }
  std::sort(order.begin(), order.end());
  std::call_once(impl_->records, [this] { buildRecords(*impl_); });

  Candidates found;
  std::vector<uint32_t> prims;
  std::vector<float> bounds;
  double extra = kReachMin * m.mean_radius;
  uint32_t hint = UINT32_MAX;
  for (size_t i = 0, j = 0; i < order.size(); i = j) {
    j = i + 1;
    while (j < order.size() && order[j].first == order[i].first) ++j;
    Vec3d lo = points[order[i].second], hi = lo;
    for (size_t k = i + 1; k < j; ++k)
      for (int a = 0; a < 3; ++a)
        lo[a] = std::min(lo[a], points[order[k].second][a]), hi[a] = std::max(hi[a], points[order[k].second][a]);
    const double half = 0.5 * vlen(vsub(hi, lo));
    if (j - i == 1 || order[i].first == UINT64_MAX || !(half <= 2 * cell)) {
      for (size_t k = i; k < j; ++k) {  // alone, not finite, or spread out (outside the grid): one query each
        out[order[k].second] = closest(points[order[k].second], hint);
        hint = out[order[k].second].triangle;
      }
      continue;
    }
    // One gather of radius R around the run's center c holds every triangle within R of c. For a point p whose
    // best distance among those is b, a nearer triangle would lie within |p - c| + b of c: when that is at most
    // R, b is p's answer; otherwise p gets its own query.
    const Vec3d c = vmul(vadd(lo, hi), 0.5);
    const double reach = half + extra;
    const float cf[3] = {static_cast<float>(c[0] - m.origin[0]), static_cast<float>(c[1] - m.origin[1]),
                         static_cast<float>(c[2] - m.origin[2])};
    // Float rounding of the records, of c, and of the dot products: well inside 16 slacks plus 64 ulps of |c|.
    const float margin_c = 16 * m.slack + 64 * kEps * (std::abs(cf[0]) + std::abs(cf[1]) + std::abs(cf[2]));
    const float reach_f = static_cast<float>(reach) * (1 + 4 * kEps) + margin_c;
    prims.clear();
    Gather g{&m, &prims};
    RTCPointQuery query;
    query.x = cf[0], query.y = cf[1], query.z = cf[2], query.time = 0.f, query.radius = reach_f;
    RTCPointQueryContext context;
    rtcInitPointQueryContext(&context);
    rtcPointQuery(m.scene, &query, &context, gatherCallback, &g);
    found.clear();
    for (uint32_t t : prims) {
      const float* record = &m.planes[16 * size_t(t)];
      if (lowerBound2(record, cf) <= reach_f * reach_f * (1 + 16 * kEps)) found.add(record, t);
    }
    const size_t count = found.ids.size();
    bounds.resize(kLanes * found.blocks());
    double farthest = 0;
    for (size_t k = i; k < j; ++k) {
      const Vec3d& p = points[order[k].second];
      Closest& o = out[order[k].second];
      o.distance = std::numeric_limits<double>::infinity();
      o.triangle = UINT32_MAX;
      const float pf[3] = {static_cast<float>(p[0] - m.origin[0]), static_cast<float>(p[1] - m.origin[1]),
                           static_cast<float>(p[2] - m.origin[2])};
      const float margin = 16 * m.slack + 64 * kEps * (std::abs(pf[0]) + std::abs(pf[1]) + std::abs(pf[2]));
      auto test = [&](size_t n) {
        const Vec3d* t = &m.corners[3 * size_t(found.ids[n])];
        const Vec3d q = closestPointOnTriangle(p, t[0], t[1], t[2]);
        const double d2 = vdot(vsub(q, p), vsub(q, p));
        if (d2 < o.distance) o.distance = d2, o.point = q, o.triangle = found.ids[n];
      };
      // Bound below which a candidate may still be nearer than the best so far (squared, rounded up).
      auto limit = [&] {
        const float r = static_cast<float>(std::sqrt(o.distance)) * (1 + 4 * kEps) + margin;
        return r * r * (1 + 16 * kEps);
      };
      if (count) {
        lowerBounds2(found, pf, bounds.data());
        // The least bound first (nearly always the answer), then any bound still below the best distance.
        const size_t first = argminOf(bounds.data(), count);
        test(first);
        float below = limit();
        for (size_t n = 0; n < count; ++n)
          if (bounds[n] <= below && n != first) test(n), below = limit();
      }
      o.distance = std::sqrt(o.distance);
      if (!(o.distance + vlen(vsub(p, c)) <= reach))
        o = closest(p, o.triangle != UINT32_MAX ? o.triangle : hint);
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
