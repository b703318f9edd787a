// SurfaceIndex's internals, shared by its translation units (not part of the public API):
//   surface_index.cpp     build() and closestMany()
//   surface_clusters.cpp  closestMany's clusters (surface_clusters.h: their lower bounds, inline)
//   surface_morton.cpp    the Morton order of a batch of points
//   surface_embree.cpp    every Embree call: the device, the scenes, point queries (closest() and the clusters'
//                         gather) and ray queries (intersect())
// Only surface_embree.cpp includes Embree's headers: scenes are held here as opaque handles.
#pragma once

#include <cstdint>
#include <memory>
#include <mutex>
#include <span>
#include <utility>
#include <vector>

#include "engine/status.h"
#include "spatial/surface_index.h"

namespace scanpress {
namespace surface {

// An Embree scene (RTCScene) that this owns, released when it goes.
class Scene {
 public:
  Scene() = default;
  explicit Scene(void* handle) : handle_(handle) {}
  Scene(Scene&& other) noexcept : handle_(other.handle_) { other.handle_ = nullptr; }
  Scene& operator=(Scene&& other) noexcept {
    std::swap(handle_, other.handle_);
    return *this;
  }
  ~Scene();
  void* handle() const { return handle_; }  // RTCScene

 private:
  void* handle_ = nullptr;
};

constexpr size_t kLanes = 4;  // one SSE register; GCC's vector extension keeps this portable
// At most kClusterSize triangles per cluster: two blocks of kLanes.
constexpr size_t kClusterSize = 8;
static_assert(kClusterSize % kLanes == 0);

// closestMany's view of the triangles: clusters of at most kClusterSize nearby triangles (median splits), each a
// primitive of a second Embree scene (user geometry, its box as bounds), so that one gather returns a few
// clusters instead of tens of triangles. A cluster's triangles sit together:
// their plane records (plane and edge lines in float, for lower bounds) transposed in blocks of kLanes, their ids
// and their corners in double (for exact tests).
struct ClusterSet {
  Scene scene;
  std::vector<float> boxes;     // per cluster: lower xyz, 0, upper xyz, 0 (relative to the origin, rounded outward);
                                // for Embree's build, then freed
  std::vector<uint32_t> first;  // cluster k's blocks are [first[k], first[k + 1])
  std::vector<float> rows;      // per block: 16 rows of kLanes floats (row r = component r of the records)
  std::vector<uint32_t> ids;    // per slot (block * kLanes + lane): the triangle, UINT32_MAX in an unused lane
  std::vector<Vec3d> corners;   // per slot: three corners in double
};

}  // namespace surface

struct SurfaceIndex::Impl {
  std::shared_ptr<EmbreeDevice> device;
  surface::Scene scene;
  std::span<const Vec3d> positions;
  std::span<const Triangle> triangles;
  std::vector<float> vertices;  // float xyz relative to origin, padded for Embree's 16-byte loads
  std::vector<float> spheres;   // per triangle: bounding-sphere center (relative to origin) and radius
  Vec3d origin{0, 0, 0};
  float slack = 0;  // absolute float rounding of the vertices: added to every search radius
  // closestMany's clusters (see ClusterSet above), built on its first batch.
  std::unique_ptr<surface::ClusterSet> clusters;
  std::once_flag clusters_built;
  double mean_radius = 0;  // of the triangles' bounding spheres (sizes closestMany's runs)
};

namespace surface {

// surface_clusters.cpp: closestMany's clusters and their Embree scene, built on its first use (closest() and
// intersect() do without). Triangles with a corner not finite are left out: their distance is never the least.
// Null if Embree fails.
std::unique_ptr<ClusterSet> buildClusters(const SurfaceIndex::Impl& m);

// surface_embree.cpp.
// The scene of m's triangles, sharing m.vertices and m.triangles with Embree.
Result<Scene> triangleScene(const SurfaceIndex::Impl& m);
// The scene of set's clusters (user geometry over set.boxes); an empty Scene if Embree fails.
Scene clusterScene(EmbreeDevice& device, ClusterSet& set);
// Embree's gather: appends to `clusters` every cluster whose box the sphere of radius `radius` around c (relative
// to the origin) reaches, and prefetches their plane records and ids (and corners, with `corners`: a run that
// bounds its clusters in place).
void gatherClusters(const ClusterSet& set, const float c[3], float radius, bool corners,
                    std::vector<uint32_t>& clusters);

}  // namespace surface
}  // namespace scanpress
