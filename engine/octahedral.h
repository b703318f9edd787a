// Octahedral normal encoding (Meyer et al., "On floating-point normal vectors", EGSR 2010; Cigolle et al., "A
// survey of efficient representations for independent unit vectors", JCGT 2014): a unit vector maps to the square
// [-1,1]^2 by projecting onto the octahedron |x|+|y|+|z| = 1 and folding the lower half over the diagonals.
//
// Each component is stored on `bits` bits as round(c * M) + M with M = 2^(bits-1) - 1, so codes run 0 .. 2^bits-2
// and the square's center, edges and corners are exact (the six axis directions decode exactly). Encoding is the
// "precise" variant of Cigolle et al.: of the four codes around the projected point, the one whose decoded
// direction is closest to the input wins. Re-encoding a decoded normal gives back its code (or, on the folded
// square's border where two codes name one direction, the other code of that direction): no drift.
//
// Precision (measured in tests/test_quantize.cpp over 10^6 random directions): maximum angular error 0.051
// degrees at 12 bits per component (the default) and 0.16 degrees at 10 bits.
#pragma once

#include <cmath>

#include "engine/mesh.h"

namespace scanpress {

inline Vec3f decodeOctahedral(const OctNormal& e, int bits) {
  const float m = float((1u << (bits - 1)) - 1);
  float u = (float(e[0]) - m) / m;
  float v = (float(e[1]) - m) / m;
  const float z = 1.f - std::fabs(u) - std::fabs(v);
  if (z < 0.f) {
    const float fu = (1.f - std::fabs(v)) * (u >= 0.f ? 1.f : -1.f);
    const float fv = (1.f - std::fabs(u)) * (v >= 0.f ? 1.f : -1.f);
    u = fu;
    v = fv;
  }
  const float len = std::sqrt(u * u + v * v + z * z);
  return {u / len, v / len, z / len};
}

inline OctNormal encodeOctahedral(const Vec3f& n, int bits) {
  const float len = std::fabs(n[0]) + std::fabs(n[1]) + std::fabs(n[2]);
  float u = 0.f, v = 0.f;
  if (len > 0.f && std::isfinite(len)) {
    u = n[0] / len;
    v = n[1] / len;
    if (n[2] < 0.f) {
      const float fu = (1.f - std::fabs(v)) * (u >= 0.f ? 1.f : -1.f);
      const float fv = (1.f - std::fabs(u)) * (v >= 0.f ? 1.f : -1.f);
      u = fu;
      v = fv;
    }
  }
  const float m = float((1u << (bits - 1)) - 1);
  auto clampCode = [m](float c) { return static_cast<uint16_t>(c < 0.f ? 0.f : (c > 2.f * m ? 2.f * m : c)); };
  const float fu = std::floor(u * m) + m, fv = std::floor(v * m) + m;
  OctNormal best{clampCode(std::round(u * m) + m), clampCode(std::round(v * m) + m)};
  if (!(len > 0.f && std::isfinite(len))) return best;
  // In double: at 12 bits neighbouring codes differ by cos ~ 1 - 1.4e-7, below float's resolution near 1.
  double best_dot = -2.0;
  for (int du = 0; du < 2; ++du)
    for (int dv = 0; dv < 2; ++dv) {
      const OctNormal c{clampCode(fu + du), clampCode(fv + dv)};
      const Vec3f d = decodeOctahedral(c, bits);
      const double dot = double(d[0]) * n[0] + double(d[1]) * n[1] + double(d[2]) * n[2];
      if (dot > best_dot) best_dot = dot, best = c;
    }
  return best;
}

}  // namespace scanpress
