// Small exact geometry kernels in double precision.
#pragma once

#include <algorithm>
#include <cmath>
#include <limits>

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

// Closest point to p on segment ab (a itself if a == b).
inline Vec3d closestPointOnSegment(const Vec3d& p, const Vec3d& a, const Vec3d& b) {
  const Vec3d ab = vsub(b, a);
  const double len2 = vdot(ab, ab);
  if (!(len2 > 0)) return a;
  const double t = vdot(vsub(p, a), ab) / len2;
  return t <= 0 ? a : t >= 1 ? b : vadd(a, vmul(ab, t));
}

// Closest point to p on a thin triangle abc (one whose angles cannot be told apart from 0 or 180 degrees in
// the region tests below): the nearest of its three edges and, if its plane is well enough defined, of the
// projection of p onto that plane when it falls inside. The normal is the cross product of the two shortest
// edges (the most precise of the three); below a sine of 1e-8 at their corner the triangle is taken as its
// edges (every point of it is then within 1e-8 times its longest edge of an edge). Rare: kept out of line
// (cold), so that closestPointOnTriangle stays small where it is inlined (closestMany's loop).
[[gnu::cold, gnu::noinline]] inline Vec3d closestPointOnThinTriangle(const Vec3d& p, const Vec3d& a, const Vec3d& b,
                                                                     const Vec3d& c) {
  const Vec3d* v[3] = {&a, &b, &c};
  Vec3d best = a;
  double best2 = std::numeric_limits<double>::infinity();
  int longest = 0;
  double longest2 = -1;
  for (int e = 0; e < 3; ++e) {
    const Vec3d& s = *v[e];
    const Vec3d& t = *v[(e + 1) % 3];
    const Vec3d q = closestPointOnSegment(p, s, t);
    const double d2 = vdot(vsub(q, p), vsub(q, p));
    if (d2 < best2 || e == 0) best2 = d2, best = q;
    const double l2 = vdot(vsub(t, s), vsub(t, s));
    if (l2 > longest2) longest2 = l2, longest = e;
  }
  // The corner opposite the longest edge (s, t), and its edges in the order that keeps the orientation of
  // abc.
  const Vec3d& o = *v[(longest + 2) % 3];
  const Vec3d e1 = vsub(*v[longest], o), e2 = vsub(*v[(longest + 1) % 3], o);
  const Vec3d n = vcross(e1, e2);
  const double nn = vdot(n, n);
  if (!(nn > 1e-16 * vdot(e1, e1) * vdot(e2, e2))) return best;
  const Vec3d q = vsub(p, vmul(n, vdot(n, vsub(p, o)) / nn));
  for (int e = 0; e < 3; ++e)
    if (vdot(vcross(vsub(*v[(e + 1) % 3], *v[e]), vsub(q, *v[e])), n) < 0) return best;
  return vdot(vsub(q, p), vsub(q, p)) < best2 ? q : best;
}

// Closest point to p on triangle abc (Ericson, Real-Time Collision Detection, 5.1.5): Voronoi regions of the
// vertices and edges, then the face. Degenerate triangles are their segments or their point: a zero-length
// edge never takes its edge branch (its division would be 0/0), and a triangle that reaches the face branch
// while too thin for the face's barycentric coordinates to be accurate (twice its area below 1e-2 times its
// longest edge squared: their rounding error grows as the inverse square of that ratio; collinear corners
// give anything) is solved by closestPointOnThinTriangle.
inline Vec3d closestPointOnTriangle(const Vec3d& p, const Vec3d& a, const Vec3d& b, const Vec3d& c) {
  const Vec3d ab = vsub(b, a), ac = vsub(c, a), ap = vsub(p, a);
  const double d1 = vdot(ab, ap), d2 = vdot(ac, ap);
  if (d1 <= 0 && d2 <= 0) return a;
  const Vec3d bp = vsub(p, b);
  const double d3 = vdot(ab, bp), d4 = vdot(ac, bp);
  if (d3 >= 0 && d4 <= d3) return b;
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0 && d1 - d3 > 0) {
    const double v = d1 / (d1 - d3);
    return vadd(a, vmul(ab, v));
  }
  const Vec3d cp = vsub(p, c);
  const double d5 = vdot(ab, cp), d6 = vdot(ac, cp);
  if (d6 >= 0 && d5 <= d6) return c;
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0 && d2 - d6 > 0) {
    const double w = d2 / (d2 - d6);
    return vadd(a, vmul(ac, w));
  }
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0 && (d4 - d3) + (d5 - d6) > 0) {
    const double w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
    return vadd(b, vmul(vsub(c, b), w));
  }
  // denom is |ab x ac|^2 = (2 area)^2 up to rounding: below 1e-4 times the longest edge^4, the triangle is
  // thin (and if p is not finite, the thin path gives a non-finite point, as the face would).
  const double denom = va + vb + vc;
  const Vec3d bc = vsub(c, b);
  const double longest2 = std::max({vdot(ab, ab), vdot(ac, ac), vdot(bc, bc)});
  if (!(denom > 1e-4 * longest2 * longest2)) return closestPointOnThinTriangle(p, a, b, c);
  const double v = vb / denom, w = vc / denom;
  return vadd(a, vadd(vmul(ab, v), vmul(ac, w)));
}

}  // namespace scanpress
