// Helpers of the tests that query surfaces (spatial and jobs layers): one Embree device, a flat grid mesh.
#pragma once

#include <cstdint>
#include <memory>

#include "engine/mesh.h"
#include "spatial/surface_index.h"

namespace scanpress::testing {

// One Embree device for the whole test binary.
inline std::shared_ptr<EmbreeDevice> device() {
  static auto d = *EmbreeDevice::create();
  return d;
}

// An n x n grid of squares (two triangles each) of side `size` in the plane at height z.
inline Mesh grid(int n, double z, double size = 1.0) {
  Mesh m;
  for (int y = 0; y <= n; ++y)
    for (int x = 0; x <= n; ++x) m.positions.push_back({size * x / n, size * y / n, z});
  for (int y = 0; y < n; ++y)
    for (int x = 0; x < n; ++x) {
      const uint32_t a = y * (n + 1) + x;
      m.triangles.push_back({a, a + 1, a + n + 2});
      m.triangles.push_back({a, a + n + 2, a + n + 1});
    }
  return m;
}

}  // namespace scanpress::testing
