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
#include "spatial_util.h"
#include "test_util.h"

namespace scanpress {
namespace {

using testing::device;
using testing::grid;

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
    for (int k = 0; k < 3; ++k)
      m.positions.push_back({c[0] + size * u(rng), c[1] + size * u(rng), c[2] + size * u(rng)});
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
    const Vec3d q = closestPointOnTriangle(points[i], m.positions[t[0]], m.positions[t[1]], m.positions[t[2]]);
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
      for (int k = 0; k < 12; ++k)
        points.push_back({c[0] + spread * u(rng), c[1] + spread * u(rng), c[2] + spread * u(rng)});
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
  for (int k = 0; k < 50; ++k) points.push_back({0.3, 0.3, 0.0});              // one point, many times
  points.push_back({1e15, -1e15, 3e14});                                       // far outside any grid
  points.push_back({1e15, -1e15, 3e14 + 1});
  points.push_back({-2e9, 0.5, 0.5});
  for (int k = 0; k < 20; ++k) points.push_back({5.0 + 1e-4 * k, 5.0, 5.0});  // a run far from the surface
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
    if (std::isnan(one.distance)) EXPECT_TRUE(std::isnan(many[i].distance)) << "point " << i;
    else EXPECT_EQ(many[i].distance, one.distance) << "point " << i;
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

// Degenerate and thin triangles (issue 18): an independent reference in long double that takes a triangle as
// the union of its face (solving the 2x2 normal equations, only if their determinant is clearly nonzero) and
// its three edge segments (a zero-length one is a point).
long double exactDistance(const Vec3d& pd, const Vec3d& ad, const Vec3d& bd, const Vec3d& cd) {
  using L = long double;
  const L p[3] = {pd[0], pd[1], pd[2]}, a[3] = {ad[0], ad[1], ad[2]}, b[3] = {bd[0], bd[1], bd[2]},
          c[3] = {cd[0], cd[1], cd[2]};
  auto dot = [](const L* u, const L* v) { return u[0] * v[0] + u[1] * v[1] + u[2] * v[2]; };
  auto segment = [&](const L* s, const L* e) {
    const L d[3] = {e[0] - s[0], e[1] - s[1], e[2] - s[2]}, sp[3] = {p[0] - s[0], p[1] - s[1], p[2] - s[2]};
    const L len2 = dot(d, d);
    const L t = len2 > 0 ? std::clamp(dot(sp, d) / len2, L(0), L(1)) : L(0);
    const L r[3] = {sp[0] - t * d[0], sp[1] - t * d[1], sp[2] - t * d[2]};
    return std::sqrt(dot(r, r));
  };
  L best = std::min({segment(a, b), segment(b, c), segment(c, a)});
  const L u[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]}, v[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]},
          w[3] = {p[0] - a[0], p[1] - a[1], p[2] - a[2]};
  const L uu = dot(u, u), uv = dot(u, v), vv = dot(v, v), uw = dot(u, w), vw = dot(v, w);
  const L det = uu * vv - uv * uv;
  if (det > 1e-12L * uu * vv) {
    const L s = (vv * uw - uv * vw) / det, t = (uu * vw - uv * uw) / det;
    if (s >= 0 && t >= 0 && s + t <= 1) {
      const L r[3] = {w[0] - s * u[0] - t * v[0], w[1] - s * u[1] - t * v[1], w[2] - s * u[2] - t * v[2]};
      best = std::min(best, std::sqrt(dot(r, r)));
    }
  }
  return best;
}

double exactDistance(const Mesh& m, const Vec3d& p) {
  long double best = std::numeric_limits<long double>::infinity();
  for (const auto& t : m.triangles)
    best = std::min(best, exactDistance(p, m.positions[t[0]], m.positions[t[1]], m.positions[t[2]]));
  return double(best);
}

// A 10x10 grid over [0,1]^2 (z = 0) plus degenerate triangles of every kind, off the grid (z = 0.2 .. 0.3, so
// that they are the nearest surface of some points) and on it (reusing the grid's vertices: they add nothing
// to the surface, and points on the grid must stay at distance 0): (i,i,j), (i,j,j), (i,j,i), (i,i,i),
// collinear, nearly collinear and needles.
Mesh gridWithDegenerateTriangles(std::mt19937& rng) {
  Mesh m = grid(10, 0.0);
  std::uniform_real_distribution<double> u(0, 1);
  std::uniform_int_distribution<uint32_t> vertex(0, uint32_t(m.positions.size()) - 1);
  auto add = [&m](const Vec3d& p) {
    m.positions.push_back(p);
    return uint32_t(m.positions.size() - 1);
  };
  for (int k = 0; k < 40; ++k) {
    const Vec3d a{u(rng), u(rng), 0.2 + 0.1 * u(rng)};
    const Vec3d b{a[0] + 0.2 * (u(rng) - 0.5), a[1] + 0.2 * (u(rng) - 0.5), a[2] + 0.05 * (u(rng) - 0.5)};
    const uint32_t i = add(a), j = add(b);
    // (i,i,j), (i,j,j), (i,j,i), (i,i,i); collinear with the third corner inside, then beyond; nearly
    // collinear (1e-12 off); a needle (its third corner 2.4e-9 from j).
    const int kind = k % 8;
    const uint32_t third = kind == 4   ? add(vadd(a, vmul(vsub(b, a), 0.37)))
                           : kind == 5 ? add(vadd(a, vmul(vsub(b, a), 1.6)))
                           : kind == 6 ? add(vadd(vadd(a, vmul(vsub(b, a), 0.5)), {0, 0, 1e-12}))
                                       : add(vadd(b, {1e-9, -2e-9, 1e-9}));
    const Triangle kinds[8] = {{i, i, j},     {i, j, j},     {i, j, i},     {i, i, i},
                               {i, j, third}, {i, third, j}, {i, j, third}, {i, j, third}};
    m.triangles.push_back(kinds[kind]);
  }
  for (int k = 0; k < 200; ++k) {  // on the grid
    const Triangle& t = m.triangles[k % 200];
    const uint32_t x = vertex(rng);
    // A repeated corner of a grid triangle (either side), a point, three collinear vertices (the first row).
    const Triangle kinds[4] = {{t[0], t[0], t[1]}, {t[1], t[2], t[2]}, {x, x, x}, {0, 5, 10}};
    m.triangles.push_back(kinds[k % 4]);
  }
  return m;
}

TEST(Measure, DegenerateTrianglesAreTheirSegmentsOrPoints) {
  // closestPointOnTriangle against the reference, triangle by triangle, for points all around each.
  std::mt19937 rng(18);
  const Mesh m = gridWithDegenerateTriangles(rng);
  std::uniform_real_distribution<double> u(-1, 1);
  for (const auto& t : m.triangles) {
    const Vec3d &a = m.positions[t[0]], &b = m.positions[t[1]], &c = m.positions[t[2]];
    for (int k = 0; k < 200; ++k) {
      const double spread = k % 3 == 0 ? 1e-3 : k % 3 == 1 ? 0.05 : 0.5;
      const Vec3d on = vadd(a, vadd(vmul(vsub(b, a), 0.5 + 0.7 * u(rng)), vmul(vsub(c, a), 0.5 + 0.7 * u(rng))));
      const Vec3d p{on[0] + spread * u(rng), on[1] + spread * u(rng), on[2] + spread * u(rng)};
      const Vec3d q = closestPointOnTriangle(p, a, b, c);
      const double ref = double(exactDistance(p, a, b, c));
      ASSERT_NEAR(vlen(vsub(q, p)), ref, 1e-12) << "triangle (" << t[0] << "," << t[1] << "," << t[2] << ") " << k;
    }
  }
}

TEST(Measure, ClosestWithDegenerateTrianglesMatchesTheReference) {
  // Both closest() and closestMany() against the reference, for points near the degenerate triangles, points
  // on the grid (distance 0 whatever the degenerate triangles on it) and points around it.
  std::mt19937 rng(1818);
  const Mesh m = gridWithDegenerateTriangles(rng);
  std::uniform_real_distribution<double> u(-1, 1), unit(0, 1);
  std::vector<Vec3d> points, on_grid;
  for (size_t t = 200; t < 240; ++t) {  // the off-grid degenerate ones
    const Vec3d& a = m.positions[m.triangles[t][0]];
    const Vec3d& b = m.positions[m.triangles[t][2]];
    for (int k = 0; k < 25; ++k) {
      const Vec3d on = vadd(a, vmul(vsub(b, a), 1.2 * unit(rng) - 0.1));
      const double spread = k % 2 ? 1e-3 : 0.03;
      points.push_back({on[0] + spread * u(rng), on[1] + spread * u(rng), on[2] + spread * u(rng)});
    }
  }
  for (int k = 0; k < 2000; ++k) on_grid.push_back({unit(rng), unit(rng), 0.0});
  for (int k = 0; k < 1000; ++k) points.push_back({0.5 + u(rng), 0.5 + u(rng), 0.3 * u(rng)});
  points.insert(points.end(), on_grid.begin(), on_grid.end());
  auto index = SurfaceIndex::build(device(), m.positions, m.triangles);
  ASSERT_TRUE(index.isOk());
  std::vector<SurfaceIndex::Closest> many(points.size());
  index->closestMany(points, many);
  uint32_t hint = UINT32_MAX;
  for (size_t i = 0; i < points.size(); ++i) {
    const double ref = exactDistance(m, points[i]);
    const auto one = index->closest(points[i]), hinted = index->closest(points[i], hint);
    hint = one.triangle;
    ASSERT_NEAR(one.distance, ref, 1e-12) << "point " << i;
    ASSERT_NEAR(hinted.distance, ref, 1e-12) << "point " << i;
    ASSERT_NEAR(many[i].distance, ref, 1e-12) << "point " << i;
  }
  expectSameAsOneByOne(*index, m, points);
}

}  // namespace
}  // namespace scanpress
