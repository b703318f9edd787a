#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <random>

#include "engine/octahedral.h"
#include "engine/quantize.h"
#include "test_util.h"

namespace scanpress {
namespace {

TEST(Grid, CubicCellsOverLargestExtent) {
  BoundingBox box;
  box.extend({-1, 0, 2});
  box.extend({3, 1, 2.5});
  auto g = makeGrid(box, 12);
  ASSERT_TRUE(g.isOk());
  EXPECT_EQ(g->bits, 12);
  EXPECT_DOUBLE_EQ(g->cell, 4.0 / 4096);
  EXPECT_EQ(g->origin, (Vec3d{-1, 0, 2}));
  EXPECT_EQ(g->quantize({-1, 0, 2}), (Vec3u{0, 0, 0}));
  EXPECT_EQ(g->quantize({3, 1, 2.5}), (Vec3u{4095, 1024, 512}));  // the max corner clamps into the last cell
  // Every cell center requantizes to its cell, and the error is at most half a cell per axis.
  std::mt19937 rng(1);
  for (int i = 0; i < 10000; ++i) {
    Vec3d p{-1 + 4.0 * (rng() / 4294967296.0), 1.0 * (rng() / 4294967296.0), 2 + 0.5 * (rng() / 4294967296.0)};
    const Vec3u q = g->quantize(p);
    const Vec3d c = g->dequantize(q);
    for (int a = 0; a < 3; ++a) EXPECT_LE(std::abs(c[a] - p[a]), g->cell / 2 * (1 + 1e-9));
    EXPECT_EQ(g->quantize(c), q);
  }
}

TEST(Grid, RejectsBadBitsAndEmptyBoxes) {
  BoundingBox box;
  EXPECT_EQ(makeGrid(box, 16).status().code(), ErrorCode::kMalformed);
  box.extend({0, 0, 0});
  EXPECT_EQ(makeGrid(box, 7).status().code(), ErrorCode::kInvalidArgument);
  EXPECT_EQ(makeGrid(box, 25).status().code(), ErrorCode::kInvalidArgument);
  EXPECT_TRUE(makeGrid(box, 8).isOk());  // a single point still gets a valid grid
  box.extend({1e308, 0, 0});
  box.extend({-1e308, 0, 0});
  EXPECT_EQ(makeGrid(box, 16).status().code(), ErrorCode::kUnsupported);
}

TEST(Quantize, DropsDegenerateTrianglesAndUnreferencedVertices) {
  Mesh m = testing::octahedron();
  m.positions.push_back({0.5, 0.5, 0.5});     // 6: unreferenced
  m.positions.push_back({1.0 + 1e-9, 0, 0});  // 7: same cell as vertex 0
  m.triangles.push_back({0, 7, 2});           // degenerate after quantization
  m.triangles.push_back({3, 3, 4});           // degenerate in the input
  QuantizeStats stats;
  auto grid = makeGrid(boundingBox(m), 10);
  ASSERT_TRUE(grid.isOk());
  auto q = quantizeMesh(m, *grid, {}, &stats);
  ASSERT_TRUE(q.isOk());
  EXPECT_EQ(stats.degenerate_triangles, 2u);
  EXPECT_EQ(stats.unreferenced_vertices, 2u);
  EXPECT_EQ(q->positions.size(), 6u);
  EXPECT_EQ(q->triangles.size(), 8u);
  // Kept vertices keep their order.
  for (size_t i = 0; i < 6; ++i) EXPECT_EQ(q->positions[i], grid->quantize(m.positions[i]));
}

TEST(Octahedral, PrecisionAsDocumented) {
  std::mt19937 rng(2);
  std::normal_distribution<float> n(0, 1);
  double worst10 = 0, worst12 = 0;
  for (int i = 0; i < 1000000; ++i) {
    Vec3f v{n(rng), n(rng), n(rng)};
    const float len = std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
    if (len < 1e-6f) continue;
    for (auto& c : v) c /= len;
    for (int bits : {10, 12}) {
      const Vec3f d = decodeOctahedral(encodeOctahedral(v, bits), bits);
      const double dot = std::min(1.0, double(v[0]) * d[0] + double(v[1]) * d[1] + double(v[2]) * d[2]);
      const double deg = std::acos(dot) * 180.0 / M_PI;
      (bits == 10 ? worst10 : worst12) = std::max(bits == 10 ? worst10 : worst12, deg);
    }
  }
  EXPECT_LT(worst12, 0.055);
  EXPECT_LT(worst10, 0.17);
  std::printf("octahedral max angular error: %.4f deg at 10 bits, %.4f deg at 12 bits\n", worst10, worst12);
  // Re-encoding a decoded normal gives the same code.
  for (int i = 0; i < 100000; ++i) {
    const OctNormal e{static_cast<uint16_t>(rng() % 4095), static_cast<uint16_t>(rng() % 4095)};
    const OctNormal again = encodeOctahedral(decodeOctahedral(e, 12), 12);
    const Vec3f a = decodeOctahedral(e, 12), b = decodeOctahedral(again, 12);
    // Codes on the folded square's border name the same direction twice: then the directions are identical.
    if (again != e) {
      EXPECT_EQ(a, b) << e[0] << "," << e[1] << " -> " << again[0] << "," << again[1];
    }
  }
  // Axis directions are exact.
  for (Vec3f axis : {Vec3f{1, 0, 0}, Vec3f{0, -1, 0}, Vec3f{0, 0, 1}, Vec3f{0, 0, -1}}) {
    const Vec3f d = decodeOctahedral(encodeOctahedral(axis, 12), 12);
    for (int a = 0; a < 3; ++a) EXPECT_NEAR(d[a], axis[a], 1e-6);
  }
}

}  // namespace
}  // namespace scanpress
