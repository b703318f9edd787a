// Small exact geometry kernels in double precision.
#pragma once

#include <cmath>

#include "engine/mesh.h"

namespace scanpress {

inline Vec3d vsub(const Vec3d& a, const Vec3d& b) { return {a[0] - b[0], a[1] - b[1], a[2] - b[2]}; }
inline Vec3d vadd(const Vec3d& a, const Vec3d& b) { return {a[0] + b[0], a[1] + b[1], a[2] + b[2]}; }
inline Vec3d vmul(const Vec3d& a, double s) { return {a[0] * s, a[1] * s, a[2] * s}; }
inline double vdot(const Vec3d& a, const Vec3d& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
inline Vec3d vcross(const Vec3d& a, const Vec3d& b) {
  return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
}
inline double vlen(const Vec3d& a) { return std::sqrt(vdot(a, a)); }

inline double triangleArea(const Vec3d& a, const Vec3d& b, const Vec3d& c) {
  return 0.5 * vlen(vcross(vsub(b, a), vsub(c, a)));
}

// Closest point to p on triangle abc (Ericson, Real-Time Collision Detection, 5.1.5): Voronoi regions of the
// vertices and edges, then the face. Works for degenerate triangles (returns a point on the segment or vertex).
inline Vec3d closestPointOnTriangle(const Vec3d& p, const Vec3d& a, const Vec3d& b, const Vec3d& c) {
  const Vec3d ab = vsub(b, a), ac = vsub(c, a), ap = vsub(p, a);
  const double d1 = vdot(ab, ap), d2 = vdot(ac, ap);
  if (d1 <= 0 && d2 <= 0) return a;
  const Vec3d bp = vsub(p, b);
  const double d3 = vdot(ab, bp), d4 = vdot(ac, bp);
  if (d3 >= 0 && d4 <= d3) return b;
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) {
    const double v = d1 / (d1 - d3);
    return vadd(a, vmul(ab, v));
  }
  const Vec3d cp = vsub(p, c);
  const double d5 = vdot(ab, cp), d6 = vdot(ac, cp);
  if (d6 >= 0 && d5 <= d6) return c;
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) {
    const double w = d2 / (d2 - d6);
    return vadd(a, vmul(ac, w));
  }
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) {
    const double w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
    return vadd(b, vmul(vsub(c, b), w));
  }
  const double denom = va + vb + vc;
  if (!(std::fabs(denom) > 0)) return a;  // fully degenerate: all corners coincide
  const double v = vb / denom, w = vc / denom;
  return vadd(a, vadd(vmul(ab, v), vmul(ac, w)));
}

}  // namespace scanpress
