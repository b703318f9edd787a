// Closest-point and ray queries on a triangle mesh, with Embree 3.
//
// EmbreeDevice: one per job, passed to every index (Embree devices are thread-safe and expensive to create).
// SurfaceIndex: an Embree scene over shared buffers. The caller's triangle array is given to Embree as it is
// (rtcSetSharedGeometryBuffer, no copy); positions are converted once to Embree's float format relative to an
// origin, and the caller's double positions are used for exact distances: the point-query callback computes the
// closest point on each candidate triangle in double precision and shrinks Embree's float search radius
// conservatively (inflated by the float rounding of the vertices), so the result is exact to double precision,
// not to float. The spans given to build() must outlive the index.
//
// Besides Embree's BVH, an index keeps per triangle a bounding sphere (16 bytes). closestMany's first call adds
// its clusters: per triangle a plane record (64 bytes: plane and edge lines in float, for lower bounds), its
// corners in double (72: an exact test reads one place instead of four) and its id (4), in clusters of up to 8
// nearby triangles stored in blocks of 4 (a cluster's unused lanes cost the same), per cluster an offset (4), and
// a second, small Embree scene over the clusters (built from the clusters' boxes, 32 bytes each, freed after):
// about 160 bytes per triangle in all.
//
// Thread safety: closest(), closestMany() and intersect() may be called from many threads at once.
#pragma once

#include <limits>
#include <memory>
#include <span>
#include <string>

#include "engine/mesh.h"
#include "engine/status.h"

namespace scanpress {

class EmbreeDevice {
 public:
  static Result<std::shared_ptr<EmbreeDevice>> create();
  ~EmbreeDevice();
  void* handle() const { return device_; }  // RTCDevice
  // The last error Embree reported on this device ("" if none).
  std::string lastError() const;
  struct ErrorSlot;  // defined in surface_embree.cpp (Embree's error callback writes it)

 private:
  EmbreeDevice() = default;
  void* device_ = nullptr;
  std::unique_ptr<ErrorSlot> error_;
};

class SurfaceIndex {
 public:
  // `origin`: what the float coordinates are relative to (default: the box centre). Indexes of pieces of one
  // surface built around one origin round a shared corner alike, so rays cannot slip between them.
  static Result<SurfaceIndex> build(std::shared_ptr<EmbreeDevice> device, std::span<const Vec3d> positions,
                                    std::span<const Triangle> triangles, const Vec3d* origin = nullptr);
  SurfaceIndex(SurfaceIndex&&) noexcept;
  SurfaceIndex& operator=(SurfaceIndex&&) noexcept;
  ~SurfaceIndex();

  struct Closest {
    double distance = 0;
    double distance_squared = 0;  // what distance is the square root of
    Vec3d point{0, 0, 0};
    uint32_t triangle = UINT32_MAX;  // UINT32_MAX when the mesh has no triangle
  };
  // With a hint (a triangle likely near p, e.g. the previous answer for a nearby query), the search starts from
  // the distance to that triangle instead of an unbounded radius: the same exact result, far fewer nodes.
  // With `within_squared` finite, only triangles closer than its square root are looked for: when none is, the
  // answer has distance infinity and triangle UINT32_MAX (for the nearest over several indexes, pass the best
  // squared distance so far: squares, so that the minimum is taken on the same values one index would compare).
  Closest closest(const Vec3d& p, uint32_t hint = UINT32_MAX,
                  double within_squared = std::numeric_limits<double>::infinity()) const;
  // closest() for many points, out[i] for points[i], the same exact distances. Meant for points that come in
  // runs of neighbours (surface samples in triangle order): points are ordered along a Morton curve and cut into
  // runs; a run shares one Embree query on the cluster scene that gathers every cluster that can hold the nearest
  // triangle of any of its points, and each point then takes the minimum over those clusters' triangles,
  // certified exact against the gather's radius (else it gathers the clusters within its best distance itself).
  // Faster than closest() one by one (bench/RESULTS.md); it costs the cluster records above.
  void closestMany(std::span<const Vec3d> points, std::span<Closest> out) const;

  struct Hit {
    bool hit = false;
    double t = 0;
    uint32_t triangle = 0;
    Vec3d normal{0, 0, 1};  // geometric, unit length, facing the ray origin
  };
  Hit intersect(const Vec3d& origin, const Vec3d& direction) const;

  size_t triangleCount() const;
  struct Impl;  // defined in surface_index_internal.h (shared by the surface_*.cpp parts)

 private:
  SurfaceIndex() = default;
  std::unique_ptr<Impl> impl_;
};

}  // namespace scanpress
