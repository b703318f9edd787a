// Helpers shared by the tests of every layer (standard library and the engine only; the jobs tests' helpers
// that run the CLI or find the shared scans are in jobs_util.h).
#pragma once

#include <algorithm>
#include <cmath>
#include <compare>
#include <array>

#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "engine/mesh.h"
#include "engine/octahedral.h"
#include "engine/quantize.h"
#include "engine/shapes.h"

namespace scanpress::testing {

// Randomized and exhaustive hostile-input loops run `n` trials in the Release lane and a quarter of them under the
// sanitizers (CI's ASan+UBSan lane runs about five times slower and covers the same decoders with the fuzz lane):
// `sampled(n)`; `sampleStride()` is the step through a payload's cuts (1, or 4 under the sanitizers).
#if defined(__SANITIZE_ADDRESS__)
inline constexpr int kSanitizerSampling = 4;
#else
inline constexpr int kSanitizerSampling = 1;
#endif
inline int sampled(int n) { return std::max(1, n / kSanitizerSampling); }
inline size_t sampleStride() { return size_t(kSanitizerSampling); }

// `m` on a grid of `bits` over its bounding box, with `layout`'s attributes (a failed quantization fails the test).
inline QuantizedMesh quantized(const Mesh& m, int bits, const AttributeLayout& layout = {}) {
  auto grid = makeGrid(boundingBox(m), bits);
  EXPECT_TRUE(grid.isOk());
  if (!grid.isOk()) return {};
  auto q = quantizeMesh(m, *grid, layout, nullptr);
  EXPECT_TRUE(q.isOk());
  return q.isOk() ? *std::move(q) : QuantizedMesh{};
}

// icosphere(levels) with the scan-like attributes the codec tests use: each vertex's normal is its position (the
// sphere's outward normal), its color RGB (128 + 100 x, 128 + 100 y, 128 + 100 z).
inline Mesh coloredIcosphere(int levels) {
  Mesh sphere = icosphere(levels);
  for (const auto& p : sphere.positions) {
    sphere.normals.push_back({float(p[0]), float(p[1]), float(p[2])});
    sphere.colors.push_back({uint8_t(128 + 100 * p[0]), uint8_t(128 + 100 * p[1]), uint8_t(128 + 100 * p[2]), 255});
  }
  sphere.color_channels = 3;
  return sphere;
}

// A mesh given as grid positions and triangles, as they are (nothing checked).
inline QuantizedMesh rawMesh(std::vector<Vec3u> positions, std::vector<Triangle> triangles) {
  QuantizedMesh m;
  m.positions = std::move(positions);
  m.triangles = std::move(triangles);
  return m;
}

// A triangle over positions, rotated so that its smallest corner comes first (orientation kept).
using PosTriangle = std::array<Vec3u, 3>;

inline std::vector<PosTriangle> triangleMultiset(const QuantizedMesh& m) {
  std::vector<PosTriangle> out;
  out.reserve(m.triangles.size());
  for (const auto& t : m.triangles) {
    PosTriangle p{m.positions[t[0]], m.positions[t[1]], m.positions[t[2]]};
    const int k = static_cast<int>(std::min_element(p.begin(), p.end()) - p.begin());
    std::rotate(p.begin(), p.begin() + k, p.end());
    out.push_back(p);
  }
  std::sort(out.begin(), out.end());
  return out;
}

// A triangle corner with its attributes (normal as a direction rounded to 1e-5, so that the two codes of one
// direction on the octahedral fold compare equal).
struct Corner {
  Vec3u p;
  std::array<int32_t, 3> n;
  Rgba8 c;
  auto operator<=>(const Corner&) const = default;
};

// Triangles with attributed corners, each rotated so that its smallest position comes first (orientation kept),
// sorted: equal for two meshes when they have the same triangles with the same attributes, whatever the vertex
// order or the tiling.
inline std::vector<std::array<Corner, 3>> cornerMultiset(const QuantizedMesh& m, int normal_bits) {
  auto corner = [&](uint32_t v) {
    Corner c{m.positions[v], {0, 0, 0}, m.colors.empty() ? Rgba8{0, 0, 0, 0} : m.colors[v]};
    if (!m.normals.empty()) {
      const Vec3f d = decodeOctahedral(m.normals[v], normal_bits);
      for (int a = 0; a < 3; ++a) c.n[a] = static_cast<int32_t>(std::lround(d[a] * 1e5));
    }
    return c;
  };
  std::vector<std::array<Corner, 3>> out;
  out.reserve(m.triangles.size());
  for (const auto& t : m.triangles) {
    std::array<Corner, 3> tri{corner(t[0]), corner(t[1]), corner(t[2])};
    const int k = static_cast<int>(std::min_element(tri.begin(), tri.end(),
                                                    [](const Corner& a, const Corner& b) { return a.p < b.p; }) -
                                   tri.begin());
    std::rotate(tri.begin(), tri.begin() + k, tri.end());
    out.push_back(tri);
  }
  std::sort(out.begin(), out.end());
  return out;
}

// Whether two octahedral normal arrays name the same directions (codes may differ on the fold border).
inline bool sameNormalDirections(const std::vector<OctNormal>& a, const std::vector<OctNormal>& b, int bits) {
  if (a.size() != b.size()) return false;
  for (size_t i = 0; i < a.size(); ++i) {
    if (a[i] == b[i]) continue;
    const Vec3f x = decodeOctahedral(a[i], bits), y = decodeOctahedral(b[i], bits);
    if (x[0] * y[0] + x[1] * y[1] + x[2] * y[2] < 1.f - 1e-6f) return false;
  }
  return true;
}

// A fresh temporary directory, removed with the object.
class TempDir {
 public:
  TempDir() {
    std::string templ = (std::filesystem::temp_directory_path() / "scanpress-test-XXXXXX").string();
    path_ = ::mkdtemp(templ.data());
  }
  ~TempDir() {
    std::error_code ec;
    std::filesystem::remove_all(path_, ec);
  }
  std::string file(const std::string& name) const { return path_ + "/" + name; }
  const std::string& path() const { return path_; }

 private:
  std::string path_;
};

// The vertices of `coarse` (a coarse level of a tile of `tile`'s points, on a grid of `bits` bits) whose normal and
// color are those of no point of `tile` in the vertex's cell of level `level` (cells of 2^(bits - level) grid cells,
// aligned to the grid): what kdtree's and octree's coarse levels show (version 3, FORMAT.md).
inline size_t verticesShowingNoPointOfTheirCell(const QuantizedMesh& tile, const QuantizedMesh& coarse, int bits,
                                                int level) {
  const int shift = bits - level;
  const auto cell = [&](const Vec3u& p) { return Vec3u{p[0] >> shift, p[1] >> shift, p[2] >> shift}; };
  std::map<Vec3u, std::vector<std::pair<OctNormal, Rgba8>>> in_cell;
  for (size_t v = 0; v < tile.positions.size(); ++v)
    in_cell[cell(tile.positions[v])].push_back({tile.normals.empty() ? OctNormal{0, 0} : tile.normals[v],
                                                tile.colors.empty() ? Rgba8{0, 0, 0, 0} : tile.colors[v]});
  size_t bad = 0;
  for (size_t v = 0; v < coarse.positions.size(); ++v) {
    const std::pair<OctNormal, Rgba8> shown{coarse.normals.empty() ? OctNormal{0, 0} : coarse.normals[v],
                                            coarse.colors.empty() ? Rgba8{0, 0, 0, 0} : coarse.colors[v]};
    const auto it = in_cell.find(cell(coarse.positions[v]));
    bad += it == in_cell.end() || std::find(it->second.begin(), it->second.end(), shown) == it->second.end();
  }
  return bad;
}

inline void writeBytes(const std::string& path, const std::string& bytes) {
  std::ofstream(path, std::ios::binary).write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
}

// A whole file as a string ("" when it cannot be read).
inline std::string readText(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(f), {});
}

inline std::vector<uint8_t> readBytes(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  return std::vector<uint8_t>(std::istreambuf_iterator<char>(f), {});
}

// The bytes of a value, little endian (or big endian), for building binary test files.
template <typename T>
std::string bytesOf(T v, bool big_endian = false) {
  std::string s(sizeof(T), '\0');
  std::memcpy(s.data(), &v, sizeof(T));
  if (big_endian) std::reverse(s.begin(), s.end());
  return s;
}

// A small closed mesh: an octahedron scaled by `s`.
inline Mesh octahedron(double s = 1.0) {
  Mesh m;
  m.positions = {{s, 0, 0}, {-s, 0, 0}, {0, s, 0}, {0, -s, 0}, {0, 0, s}, {0, 0, -s}};
  m.triangles = {{0, 2, 4}, {2, 1, 4}, {1, 3, 4}, {3, 0, 4}, {2, 0, 5}, {1, 2, 5}, {3, 1, 5}, {0, 3, 5}};
  return m;
}

// A tile with a locked border: the triangles of `sphere` (on a grid of 2^bits cells, centred) whose corners' z
// sum exceeds 3 * (centre + lift), and lock flags on the vertices of its rim (the edges one triangle uses), which
// are listed in `rim` (lower index first).
struct LockedCap {
  QuantizedMesh mesh;
  std::vector<uint8_t> locked;
  std::vector<std::pair<uint32_t, uint32_t>> rim;
};
inline LockedCap lockedCap(const QuantizedMesh& sphere, int bits, double lift) {
  LockedCap c;
  c.mesh.positions = sphere.positions;
  const double centre = (std::ldexp(1.0, bits) - 1) / 2;
  for (const Triangle& t : sphere.triangles)
    if (double(sphere.positions[t[0]][2]) + sphere.positions[t[1]][2] + sphere.positions[t[2]][2] > 3 * (centre + lift))
      c.mesh.triangles.push_back(t);
  std::map<std::pair<uint32_t, uint32_t>, int> uses;
  for (const Triangle& t : c.mesh.triangles)
    for (int k = 0; k < 3; ++k) ++uses[std::minmax(t[size_t(k)], t[size_t((k + 1) % 3)])];
  c.locked.assign(c.mesh.positions.size(), 0);
  for (const auto& [e, n] : uses)
    if (n == 1) {
      c.locked[e.first] = c.locked[e.second] = 1;
      c.rim.push_back(e);
    }
  return c;
}

// A normal per corner of `m` (3 per triangle, in triangle order) split at its sharp edges, as CAD and scan tools
// write them: the mean of the unit normals of the corner's vertex's faces within `degrees` of the corner's face
// (smooth across gentle edges, apart across sharp ones).
inline std::vector<std::array<double, 3>> cornerNormalsSplitAt(const Mesh& m, double degrees) {
  std::vector<std::array<double, 3>> face_normal;
  std::vector<std::vector<uint32_t>> faces_of(m.positions.size());
  const auto unit = [](std::array<double, 3> n) {
    const double len = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
    for (double& x : n) x /= len > 0 ? len : 1;
    return n;
  };
  for (size_t f = 0; f < m.triangles.size(); ++f) {
    const Triangle& t = m.triangles[f];
    const Vec3d &a = m.positions[t[0]], &b = m.positions[t[1]], &c = m.positions[t[2]];
    const Vec3d u{b[0] - a[0], b[1] - a[1], b[2] - a[2]}, w{c[0] - a[0], c[1] - a[1], c[2] - a[2]};
    face_normal.push_back(unit({u[1] * w[2] - u[2] * w[1], u[2] * w[0] - u[0] * w[2], u[0] * w[1] - u[1] * w[0]}));
    for (uint32_t v : t) faces_of[v].push_back(uint32_t(f));
  }
  const double limit = std::cos(degrees * M_PI / 180);
  std::vector<std::array<double, 3>> out;
  for (size_t f = 0; f < m.triangles.size(); ++f)
    for (uint32_t v : m.triangles[f]) {
      std::array<double, 3> sum{0, 0, 0};
      for (uint32_t g : faces_of[v]) {
        const auto &a = face_normal[f], &b = face_normal[g];
        if (a[0] * b[0] + a[1] * b[1] + a[2] * b[2] >= limit)
          for (int k = 0; k < 3; ++k) sum[size_t(k)] += b[size_t(k)];
      }
      out.push_back(unit(sum));
    }
  return out;
}

}  // namespace scanpress::testing
