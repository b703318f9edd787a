// Every Embree call of SurfaceIndex: the device, the scenes, point queries (closest() and closestMany's gather of
// clusters) and ray queries (intersect()).
#include <embree3/rtcore.h>

#include <cmath>
#include <limits>
#include <mutex>
#include <string>
#include <vector>

#include "engine/geometry.h"
#include "spatial/surface_index.h"
#include "spatial/surface_index_internal.h"

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

namespace surface {

Scene::~Scene() {
  if (handle_) rtcReleaseScene(static_cast<RTCScene>(handle_));
}

Result<Scene> triangleScene(const SurfaceIndex::Impl& m) {
  RTCDevice dev = static_cast<RTCDevice>(m.device->handle());
  Scene scene(rtcNewScene(dev));
  RTCScene s = static_cast<RTCScene>(scene.handle());
  rtcSetSceneFlags(s, RTC_SCENE_FLAG_ROBUST);
  rtcSetSceneBuildQuality(s, RTC_BUILD_QUALITY_MEDIUM);
  if (!m.triangles.empty()) {
    RTCGeometry geom = rtcNewGeometry(dev, RTC_GEOMETRY_TYPE_TRIANGLE);
    rtcSetSharedGeometryBuffer(geom, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, m.vertices.data(), 0,
                               3 * sizeof(float), m.positions.size());
    // Triangle is std::array<uint32_t, 3>: tightly packed, shared with Embree as it is.
    static_assert(sizeof(Triangle) == 3 * sizeof(uint32_t));
    rtcSetSharedGeometryBuffer(geom, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, m.triangles.data(), 0,
                               sizeof(Triangle), m.triangles.size());
    rtcCommitGeometry(geom);
    rtcAttachGeometry(s, geom);
    rtcReleaseGeometry(geom);
  }
  rtcCommitScene(s);
  if (rtcGetDeviceError(dev) != RTC_ERROR_NONE)
    return makeError(ErrorCode::kInternal, "building the Embree scene failed: " + m.device->lastError());
  return scene;
}

namespace {

void clusterBounds(const RTCBoundsFunctionArguments* args) {
  const float* b = &static_cast<const ClusterSet*>(args->geometryUserPtr)->boxes[8 * size_t(args->primID)];
  args->bounds_o->lower_x = b[0], args->bounds_o->lower_y = b[1], args->bounds_o->lower_z = b[2];
  args->bounds_o->upper_x = b[4], args->bounds_o->upper_y = b[5], args->bounds_o->upper_z = b[6];
}

}  // namespace

Scene clusterScene(EmbreeDevice& device, ClusterSet& set) {
  RTCDevice dev = static_cast<RTCDevice>(device.handle());
  const size_t clusters = set.first.size() - 1;
  Scene out(rtcNewScene(dev));
  RTCScene scene = static_cast<RTCScene>(out.handle());
  rtcSetSceneBuildQuality(scene, RTC_BUILD_QUALITY_HIGH);
  if (clusters > 0) {
    RTCGeometry geom = rtcNewGeometry(dev, RTC_GEOMETRY_TYPE_USER);
    rtcSetGeometryUserPrimitiveCount(geom, unsigned(clusters));
    rtcSetGeometryUserData(geom, &set);
    rtcSetGeometryBoundsFunction(geom, clusterBounds, nullptr);
    rtcCommitGeometry(geom);
    rtcAttachGeometry(scene, geom);
    rtcReleaseGeometry(geom);
  }
  rtcCommitScene(scene);
  if (rtcGetDeviceError(dev) != RTC_ERROR_NONE) return Scene();
  return out;
}

namespace {

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

}  // namespace

void gatherClusters(const ClusterSet& set, const float c[3], float radius, bool corners,
                    std::vector<uint32_t>& clusters) {
  Gather callback{&set, &clusters, corners};
  RTCPointQuery query;
  query.x = c[0], query.y = c[1], query.z = c[2], query.time = 0.f, query.radius = radius;
  RTCPointQueryContext context;
  rtcInitPointQueryContext(&context);
  rtcPointQuery(static_cast<RTCScene>(set.scene.handle()), &query, &context, gatherCallback, &callback);
}

}  // namespace surface

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

bool closestCallback(RTCPointQueryFunctionArguments* args) {
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

}  // namespace

SurfaceIndex::Closest SurfaceIndex::closest(const Vec3d& p, uint32_t hint, double within_squared) const {
  Closest out;
  if (impl_->triangles.empty()) {
    out.distance = out.distance_squared = std::numeric_limits<double>::infinity();
    return out;
  }
  ClosestQuery q{impl_.get(), p, std::numeric_limits<double>::infinity(), p, UINT32_MAX, 0,
                 0,           0, std::numeric_limits<float>::infinity()};
  RTCPointQuery query;
  query.x = q.px = static_cast<float>(p[0] - impl_->origin[0]);
  query.y = q.py = static_cast<float>(p[1] - impl_->origin[1]);
  query.z = q.pz = static_cast<float>(p[2] - impl_->origin[2]);
  query.time = 0.f;
  query.radius = std::numeric_limits<float>::infinity();
  if (within_squared < std::numeric_limits<double>::infinity()) {  // only strictly closer triangles are taken
    q.best_d2 = within_squared;
    query.radius = q.best_f = static_cast<float>(std::sqrt(within_squared)) *
                                  (1.0f + 4 * std::numeric_limits<float>::epsilon()) +
                              impl_->slack;
  }
  if (hint < impl_->triangles.size()) {
    const Triangle& t = impl_->triangles[hint];
    const Vec3d c = closestPointOnTriangle(p, impl_->positions[t[0]], impl_->positions[t[1]], impl_->positions[t[2]]);
    const Vec3d d = vsub(c, p);
    const double d2 = vdot(d, d);
    // NaN when p is not finite: then ignored, the answer is the same as without a hint
    if (!std::isnan(d2) && d2 < q.best_d2) {
      q.best_d2 = d2;
      q.best = c;
      q.triangle = hint;
      query.radius = q.best_f =
          static_cast<float>(std::sqrt(d2)) * (1.0f + 4 * std::numeric_limits<float>::epsilon()) + impl_->slack;
    }
  }
  RTCPointQueryContext context;
  rtcInitPointQueryContext(&context);
  rtcPointQuery(static_cast<RTCScene>(impl_->scene.handle()), &query, &context, closestCallback, &q);
  if (q.triangle == UINT32_MAX) {  // nothing closer than within_squared
    out.distance = out.distance_squared = std::numeric_limits<double>::infinity();
    return out;
  }
  out.distance = std::sqrt(q.best_d2);
  out.distance_squared = q.best_d2;
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
  rtcIntersect1(static_cast<RTCScene>(impl_->scene.handle()), &context, &rh);
  if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) return out;
  out.hit = true;
  out.t = rh.ray.tfar;
  out.triangle = rh.hit.primID;
  // The hit's distance and normal again in double from the triangle's own corners: the same for a triangle
  // whatever index holds it (Embree's float values depend on the index's origin), so pictures drawn a piece at a
  // time agree with whole ones.
  const Triangle& tri = impl_->triangles[out.triangle];
  const Vec3d& a = impl_->positions[tri[0]];
  Vec3d n = vcross(vsub(impl_->positions[tri[1]], a), vsub(impl_->positions[tri[2]], a));
  const double nd = vdot(n, dir);
  if (nd != 0) {
    // Kept when it agrees with Embree's: a ray grazing the plane could put the double hit far from the triangle.
    const double t = vdot(n, vsub(a, origin)) / nd;
    if (std::isfinite(t) && t >= 0 && std::fabs(t - out.t) <= 1e-4 * out.t) out.t = t;
  }
  double len = vlen(n);
  if (!(len > 0) || !std::isfinite(len)) n = {rh.hit.Ng_x, rh.hit.Ng_y, rh.hit.Ng_z}, len = vlen(n);
  n = len > 0 ? vmul(n, 1.0 / len) : Vec3d{0, 0, 1};
  if (vdot(n, dir) > 0) n = vmul(n, -1.0);
  out.normal = n;
  return out;
}

}  // namespace scanpress
