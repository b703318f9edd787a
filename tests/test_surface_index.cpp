// Closest-point queries of the surface index (spatial/surface_index.h): one by one and in batches, against an
// independent brute-force reference, on degenerate triangles, outlying and non-finite points.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <span>

#include "engine/geometry.h"
#include "engine/metro.h"
#include "spatial/surface_index.h"
#include "test_util.h"

namespace scanpress {
namespace {

std::shared_ptr<EmbreeDevice> device() {
  static auto d = *EmbreeDevice::create();
  return d;
}

Mesh grid(int n, double z, double size = 1.0) {
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

// Independent reference: distance to the triangle's plane if the projection falls inside, else the distance to
// the nearest edge segment.
double referenceDistance(const Vec3d& p, const Vec3d& a, const Vec3d& b, const Vec3d& c) {
  auto segment = [&](const Vec3d& s, const Vec3d& e) {
    const Vec3d d = vsub(e, s);
    const double len2 = vdot(d, d);
    const double t = len2 > 0 ? std::clamp(vdot(vsub(p, s), d) / len2, 0.0, 1.0) : 0.0;
    return vlen(vsub(p, vadd(s, vmul(d, t))));
  };
  const Vec3d n = vcross(vsub(b, a), vsub(c, a));
  const double n2 = vdot(n, n);
  double best = std::min({segment(a, b), segment(b, c), segment(c, a)});
  if (n2 > 0) {
    const double dist = vdot(vsub(p, a), n) / std::sqrt(n2);
    const Vec3d q = vsub(p, vmul(n, dist / std::sqrt(n2)));
    const bool inside = vdot(vcross(vsub(b, a), vsub(q, a)), n) >= 0 && vdot(vcross(vsub(c, b), vsub(q, b)), n) >= 0 &&
                        vdot(vcross(vsub(a, c), vsub(q, c)), n) >= 0;
    if (inside) best = std::min(best, std::fabs(dist));
  }
  return best;
}

// `count` separate triangles, corners within `size` of centers spread over [-3, 3]^3.
Mesh randomSoup(std::mt19937& rng, int count, double size) {
  std::uniform_real_distribution<double> u(-1, 1);
  Mesh m;
  for (int t = 0; t < count; ++t) {
    const Vec3d c{u(rng) * 3, u(rng) * 3, u(rng) * 3};
    for (int k = 0; k < 3; ++k) m.positions.push_back({c[0] + size * u(rng), c[1] + size * u(rng), c[2] + size * u(rng)});
    m.triangles.push_back({uint32_t(3 * t), uint32_t(3 * t + 1), uint32_t(3 * t + 2)});
  }
  return m;
}

double bruteForceDistance(const Mesh& m, const Vec3d& p) {
  double best = 1e300;
  for (const auto& t : m.triangles)
    best = std::min(best, referenceDistance(p, m.positions[t[0]], m.positions[t[1]], m.positions[t[2]]));
  return best;
}

TEST(Measure, RandomMeshesMatchBruteForce) {
  std::mt19937 rng(21);
  std::uniform_real_distribution<double> u(-1, 1);
  for (int round = 0; round < 5; ++round) {
    const Mesh m = randomSoup(rng, 60, 1.0);
    auto index = SurfaceIndex::build(device(), m.positions, m.triangles);
    ASSERT_TRUE(index.isOk());
    for (int q = 0; q < 2000; ++q) {
      const Vec3d p{u(rng) * 5, u(rng) * 5, u(rng) * 5};
      const double ref = bruteForceDistance(m, p);
      const auto got = index->closest(p);
      ASSERT_NEAR(got.distance, ref, 1e-6 * ref + 1e-12) << "query " << q;
      ASSERT_NEAR(vlen(vsub(got.point, p)), got.distance, 1e-12);
    }
  }
}

// closestMany must give, for every point, the distance closest() gives (the same double: both are the minimum
// of the same exact point-triangle distances), and the reported point and triangle must agree with it.
void expectSameAsOneByOne(const SurfaceIndex& index, const Mesh& m, std::span<const Vec3d> points) {
  std::vector<SurfaceIndex::Closest> many(points.size());
  index.closestMany(points, many);
  for (size_t i = 0; i < points.size(); ++i) {
    const auto one = index.closest(points[i]);
    ASSERT_EQ(many[i].distance, one.distance) << "point " << i;
    ASSERT_LT(many[i].triangle, m.triangles.size()) << "point " << i;
    ASSERT_NEAR(vlen(vsub(many[i].point, points[i])), many[i].distance, 1e-12 * (1 + many[i].distance));
    const auto& t = m.triangles[many[i].triangle];
    const Vec3d q =
        closestPointOnTriangle(points[i], m.positions[t[0]], m.positions[t[1]], m.positions[t[2]]);
    ASSERT_EQ(std::sqrt(vdot(vsub(q, points[i]), vsub(q, points[i]))), many[i].distance) << "point " << i;
  }
}

TEST(Measure, ManyQueriesMatchBruteForceOnRandomSoups) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-1, 1);
  for (int round = 0; round < 5; ++round) {
    // Tiny or large triangles against the same spread of points.
    const Mesh m = randomSoup(rng, 200, round % 2 ? 0.05 : 1.0);
    // Clusters of nearby points (they share gathers) and scattered points, interleaved.
    std::vector<Vec3d> points;
    for (int cl = 0; cl < 100; ++cl) {
      const Vec3d c{u(rng) * 4, u(rng) * 4, u(rng) * 4};
      const double spread = cl % 3 == 0 ? 1e-3 : cl % 3 == 1 ? 0.05 : 0.5;
      for (int k = 0; k < 12; ++k) points.push_back({c[0] + spread * u(rng), c[1] + spread * u(rng), c[2] + spread * u(rng)});
      points.push_back({u(rng) * 6, u(rng) * 6, u(rng) * 6});
    }
    auto index = SurfaceIndex::build(device(), m.positions, m.triangles);
    ASSERT_TRUE(index.isOk());
    std::vector<SurfaceIndex::Closest> many(points.size());
    index->closestMany(points, many);
    for (size_t q = 0; q < points.size(); ++q) {
      const double ref = bruteForceDistance(m, points[q]);
      ASSERT_NEAR(many[q].distance, ref, 1e-6 * ref + 1e-12) << "round " << round << " query " << q;
    }
    expectSameAsOneByOne(*index, m, points);
  }
}

TEST(Measure, ManyQueriesOnASurfaceAgreeWithSingleQueries) {
  // Samples of a wavy sheet against a coarser tessellation of it (the shape of a real measurement: many samples
  // per run, distances far below the triangle size), and the reverse.
  auto wavy = [](int n) {
    Mesh m = grid(n, 0.0);
    for (auto& p : m.positions) p[2] = 0.05 * std::sin(7 * p[0]) * std::cos(5 * p[1]);
    return m;
  };
  const Mesh fine = wavy(120), coarse = wavy(23);
  for (int way = 0; way < 2; ++way) {
    const Mesh& from = way ? coarse : fine;
    const Mesh& to = way ? fine : coarse;
    SampleOptions opt;
    opt.density = 40000;
    std::vector<Vec3d> samples;
    sampleSurface(from.positions, from.triangles, opt, samples);
    auto index = SurfaceIndex::build(device(), to.positions, to.triangles);
    ASSERT_TRUE(index.isOk());
    expectSameAsOneByOne(*index, to, samples);
  }
}

TEST(Measure, ManyQueriesWithDegenerateTrianglesAndOutlyingPoints) {
  Mesh m = grid(10, 0.0);
  std::vector<Vec3d> points;
  // Zero-area triangles: a repeated corner and three collinear corners.
  m.positions.push_back({0.5, 0.5, 0.2});
  m.positions.push_back({0.6, 0.5, 0.2});
  m.positions.push_back({0.7, 0.5, 0.2});
  const uint32_t a = uint32_t(m.positions.size()) - 3;
  m.triangles.push_back({a, a, a + 1});
  m.triangles.push_back({a, a + 1, a + 2});
  // A needle: its third corner 1e-12 off the line of the other two.
  m.positions.push_back({0.2, 0.2, 0.1});
  m.positions.push_back({0.8, 0.8, 0.1});
  m.positions.push_back({0.5, 0.5 + 1e-12, 0.1});
  const uint32_t b = uint32_t(m.positions.size()) - 3;
  m.triangles.push_back({b, b + 1, b + 2});
  for (int k = 0; k < 30; ++k) points.push_back({0.3 + 0.01 * k, 0.3 + 0.01 * k + 1e-4, 0.1 + 1e-4});
  for (int k = 0; k < 50; ++k) points.push_back({0.6 + 1e-3 * k, 0.5, 0.21});  // above the degenerate ones
  for (int k = 0; k < 50; ++k) points.push_back({0.3, 0.3, 0.0});             // one point, many times
  points.push_back({1e15, -1e15, 3e14});                                      // far outside any grid
  points.push_back({1e15, -1e15, 3e14 + 1});
  points.push_back({-2e9, 0.5, 0.5});
  for (int k = 0; k < 20; ++k) points.push_back({5.0 + 1e-4 * k, 5.0, 5.0});   // a run far from the surface
  auto index = SurfaceIndex::build(device(), m.positions, m.triangles);
  ASSERT_TRUE(index.isOk());
  expectSameAsOneByOne(*index, m, points);
  // Nothing to do, and a single point.
  std::vector<SurfaceIndex::Closest> none;
  index->closestMany({}, none);
  std::vector<SurfaceIndex::Closest> one(1);
  index->closestMany(std::span(points).first(1), one);
  EXPECT_EQ(one[0].distance, index->closest(points[0]).distance);
}

TEST(Measure, ManyQueriesSetNonFinitePointsApart) {
  // A non-finite point in the middle of a run of near ones (and one whose first coordinate alone is NaN) must
  // neither join the run nor change its answers; it gets what closest() gives it.
  const Mesh m = grid(10, 0.0);
  std::vector<Vec3d> points;
  for (int k = 0; k < 20; ++k) points.push_back({0.31 + 1e-3 * k, 0.32, 0.01});
  const double nan = std::numeric_limits<double>::quiet_NaN();
  points.insert(points.begin() + 5, Vec3d{nan, 0.32, 0.01});
  points.insert(points.begin() + 9, Vec3d{0.31, std::numeric_limits<double>::infinity(), 0.01});
  auto index = SurfaceIndex::build(device(), m.positions, m.triangles);
  ASSERT_TRUE(index.isOk());
  std::vector<SurfaceIndex::Closest> many(points.size());
  index->closestMany(points, many);
  for (size_t i = 0; i < points.size(); ++i) {
    const auto one = index->closest(points[i]);
    if (std::isnan(one.distance))
      EXPECT_TRUE(std::isnan(many[i].distance)) << "point " << i;
    else
      EXPECT_EQ(many[i].distance, one.distance) << "point " << i;
  }
}

TEST(Measure, ManyQueriesSpanningTheWholeDoubleRange) {
  // A batch whose extent overflows (1e308 and -1e308 apart) orders its points on a grid of zero scale; every
  // answer must still be closest()'s.
  const Mesh m = grid(10, 0.0);
  std::vector<Vec3d> points;
  for (int k = 0; k < 20; ++k) points.push_back({0.31 + 1e-3 * k, 0.32, 0.01});
  points.push_back({1e308, 0.5, 0.0});
  points.push_back({-1e308, 0.5, -1e308});
  points.push_back({0.5, 1e300, 0.0});
  auto index = SurfaceIndex::build(device(), m.positions, m.triangles);
  ASSERT_TRUE(index.isOk());
  std::vector<SurfaceIndex::Closest> many(points.size());
  index->closestMany(points, many);
  for (size_t i = 0; i < points.size(); ++i) EXPECT_EQ(many[i].distance, index->closest(points[i]).distance) << i;
}

}  // namespace
}  // namespace scanpress
