#include "spatial/surface_index.h"

#include <embree3/rtcore.h>

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
  ~Impl() {
    if (scene) rtcReleaseScene(scene);
  }
};

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
  }

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
    q.best_d2 = vdot(d, d);
    q.best = c;
    q.triangle = hint;
    query.radius = q.best_f =
        static_cast<float>(std::sqrt(q.best_d2)) * (1.0f + 4 * std::numeric_limits<float>::epsilon()) + impl_->slack;
  }
  RTCPointQueryContext context;
  rtcInitPointQueryContext(&context);
  rtcPointQuery(impl_->scene, &query, &context, closestCallback, &q);
  out.distance = std::sqrt(q.best_d2);
  out.point = q.best;
  out.triangle = q.triangle;
  return out;
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
