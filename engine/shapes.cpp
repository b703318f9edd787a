#include "engine/shapes.h"

#include <algorithm>
#include <cmath>
#include <map>

#include "engine/geometry.h"

namespace scanpress {

Mesh icosphere(int levels) {
  const double t = (1.0 + std::sqrt(5.0)) / 2.0;
  Mesh m;
  m.positions = {{-1, t, 0},  {1, t, 0},  {-1, -t, 0}, {1, -t, 0}, {0, -1, t},  {0, 1, t},
                 {0, -1, -t}, {0, 1, -t}, {t, 0, -1},  {t, 0, 1},  {-t, 0, -1}, {-t, 0, 1}};
  m.triangles = {{0, 11, 5},  {0, 5, 1},  {0, 1, 7},  {0, 7, 10}, {0, 10, 11}, {1, 5, 9}, {5, 11, 4},
                 {11, 10, 2}, {10, 7, 6}, {7, 1, 8},  {3, 9, 4},  {3, 4, 2},   {3, 2, 6}, {3, 6, 8},
                 {3, 8, 9},   {4, 9, 5},  {2, 4, 11}, {6, 2, 10}, {8, 6, 7},   {9, 8, 1}};
  auto unit = [](const Vec3d& p) { return vmul(p, 1.0 / vlen(p)); };
  for (auto& p : m.positions) p = unit(p);
  for (int l = 0; l < levels; ++l) {
    std::map<std::pair<uint32_t, uint32_t>, uint32_t> mid;
    auto midpoint = [&](uint32_t a, uint32_t b) {
      const auto key = std::minmax(a, b);
      auto it = mid.find(key);
      if (it != mid.end()) return it->second;
      m.positions.push_back(unit(vmul(vadd(m.positions[a], m.positions[b]), 0.5)));
      return mid[key] = static_cast<uint32_t>(m.positions.size() - 1);
    };
    std::vector<Triangle> next;
    next.reserve(m.triangles.size() * 4);
    for (const auto& f : m.triangles) {
      const uint32_t a = midpoint(f[0], f[1]), b = midpoint(f[1], f[2]), c = midpoint(f[2], f[0]);
      next.insert(next.end(), {Triangle{f[0], a, c}, Triangle{f[1], b, a}, Triangle{f[2], c, b}, Triangle{a, b, c}});
    }
    m.triangles = std::move(next);
  }
  return m;
}

Mesh torus(int rings, int sides, double major, double minor) {
  Mesh m;
  const double pi = 3.14159265358979323846;
  for (int i = 0; i < rings; ++i)
    for (int j = 0; j < sides; ++j) {
      const double u = 2 * pi * i / rings, v = 2 * pi * j / sides;
      m.positions.push_back({(major + minor * std::cos(v)) * std::cos(u), (major + minor * std::cos(v)) * std::sin(u),
                             minor * std::sin(v)});
    }
  const auto at = [&](int i, int j) { return uint32_t(((i + rings) % rings) * sides + (j + sides) % sides); };
  for (int i = 0; i < rings; ++i)
    for (int j = 0; j < sides; ++j) {
      m.triangles.push_back({at(i, j), at(i + 1, j), at(i + 1, j + 1)});
      m.triangles.push_back({at(i, j), at(i + 1, j + 1), at(i, j + 1)});
    }
  return m;
}

}  // namespace scanpress
