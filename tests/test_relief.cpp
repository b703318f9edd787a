// Relief construction (engine/remesh/relief.h), PRM section 2.1: every input triangle is covered exactly by its
// pieces, every relief is a height field over its plane, the refinement is conforming (a closed manifold stays a
// closed manifold), a sphere and a torus split as the geometry says, boundaries are smoother and reliefs fewer
// than with the naive per-triangle choice the paper rejects, and ugly inputs (zero-area triangles, repeated
// corners, non-manifold edges, soups, stray vertices, huge coordinates, empty meshes) come through.
#include <gtest/gtest.h>

#include <cmath>
#include <map>
#include <random>
#include <set>

#include "engine/geometry.h"
#include "engine/quantize.h"
#include "engine/remesh/relief.h"
#include "engine/shapes.h"
#include "test_util.h"

namespace scanpress {
namespace {

using testing::quantized;

Vec3d normalOf(const std::vector<Vec3d>& p, const Triangle& t) {
  return vcross(vsub(p[t[1]], p[t[0]]), vsub(p[t[2]], p[t[0]]));
}

// The checks every layout must pass: pieces cover their input triangle (in its plane, areas adding up), every
// non-degenerate piece faces its relief with a cosine of at least tau, and input vertices keep their positions.
void expectValidLayout(const QuantizedMesh& in, const ReliefLayout& r, double tau) {
  ASSERT_EQ(r.relief.size(), r.triangles.size());
  ASSERT_EQ(r.source.size(), r.triangles.size());
  ASSERT_GE(r.positions.size(), in.positions.size());
  for (size_t v = 0; v < in.positions.size(); ++v)
    for (int k = 0; k < 3; ++k) ASSERT_EQ(r.positions[v][size_t(k)], double(in.positions[v][size_t(k)]));
  std::vector<Vec3d> p_in;
  for (const Vec3u& q : in.positions) p_in.push_back({double(q[0]), double(q[1]), double(q[2])});
  std::vector<double> area(in.triangles.size(), 0);
  std::vector<int> pieces(in.triangles.size(), 0);
  for (size_t i = 0; i < r.triangles.size(); ++i) {
    const Triangle& t = r.triangles[i];
    for (uint32_t v : t) ASSERT_LT(v, r.positions.size());
    ASSERT_LT(r.relief[i], kReliefCount);
    ASSERT_LT(r.source[i], in.triangles.size());
    const uint32_t s = r.source[i];
    ++pieces[s];
    area[s] += triangleArea(r.positions[t[0]], r.positions[t[1]], r.positions[t[2]]);
    const Vec3d ns = normalOf(p_in, in.triangles[s]);
    const double len = vlen(ns);
    if (len == 0) continue;
    const Vec3d unit = vmul(ns, 1 / len);
    EXPECT_GE(alongRelief(unit, r.relief[i]), tau - 1e-12)
        << "piece " << i << " does not face relief " << int(r.relief[i]);
    // Each corner lies in the source's plane and inside it (barycentric coordinates in [0, 1]).
    const Triangle& st = in.triangles[s];
    for (uint32_t v : t) {
      const Vec3d& q = r.positions[v];
      EXPECT_LE(std::abs(vdot(vsub(q, p_in[st[0]]), unit)), 1e-9 * (1 + vlen(p_in[st[0]])));
      for (int k = 0; k < 3; ++k) {
        const Vec3d sub = normalOf({q, p_in[st[size_t((k + 1) % 3)]], p_in[st[size_t((k + 2) % 3)]]}, {0, 1, 2});
        EXPECT_GE(vdot(sub, ns) / (len * len), -1e-9) << "piece corner outside its source triangle";
      }
    }
    // Pieces keep their source's orientation.
    const Vec3d np = normalOf(r.positions, t);
    if (vlen(np) > 1e-9 * len) {
      EXPECT_GT(vdot(np, ns), 0) << "piece " << i << " flipped";
    }
  }
  for (size_t s = 0; s < in.triangles.size(); ++s) {
    EXPECT_GE(pieces[s], 1) << "input triangle " << s << " lost";
    const Triangle& t = in.triangles[s];
    const double want = triangleArea(p_in[t[0]], p_in[t[1]], p_in[t[2]]);
    EXPECT_NEAR(area[s], want, 1e-9 * (1 + want)) << "input triangle " << s;
  }
}

// Each directed edge once and its reverse once: a closed, consistently oriented 2-manifold without T-junctions.
void expectClosedManifold(const std::vector<Triangle>& triangles) {
  std::map<std::pair<uint32_t, uint32_t>, int> directed;
  for (const Triangle& t : triangles)
    for (int k = 0; k < 3; ++k) ++directed[{t[size_t(k)], t[size_t((k + 1) % 3)]}];
  for (const auto& [e, n] : directed) {
    ASSERT_EQ(n, 1) << "edge " << e.first << "-" << e.second << " used " << n << " times in one direction";
    ASSERT_EQ(directed.count({e.second, e.first}), 1u) << "edge " << e.first << "-" << e.second << " open";
  }
}

// Length of the edges between two reliefs.
double boundaryLength(const std::vector<Vec3d>& p, const std::vector<Triangle>& triangles,
                      const std::vector<uint8_t>& relief) {
  std::map<std::pair<uint32_t, uint32_t>, std::set<int>> seen;
  for (size_t i = 0; i < triangles.size(); ++i)
    for (int k = 0; k < 3; ++k) {
      const uint32_t a = triangles[i][size_t(k)], b = triangles[i][size_t((k + 1) % 3)];
      seen[std::minmax(a, b)].insert(relief[i]);
    }
  double length = 0;
  for (const auto& [e, set] : seen)
    if (set.size() > 1) length += vlen(vsub(p[e.first], p[e.second]));
  return length;
}

TEST(Relief, RefusesTauOutsideItsRangeAndBadIndices) {
  const QuantizedMesh m = quantized(icosphere(1), 10);
  for (double tau : {0.0, -0.1, 0.5774, 1.0, std::nan("")}) {
    auto r = buildReliefs(m, {}, {.tau = tau});
    ASSERT_FALSE(r.isOk()) << tau;
    EXPECT_EQ(r.status().code(), ErrorCode::kInvalidArgument);
  }
  QuantizedMesh bad = m;
  bad.triangles[3][1] = uint32_t(bad.positions.size());
  auto r = buildReliefs(bad, {}, {});
  ASSERT_FALSE(r.isOk());
  EXPECT_NE(r.status().message().find("triangle 3"), std::string::npos) << r.status().toString();
}

TEST(Relief, SphereSplitsIntoSixConnectedHeightFieldsAroundItsPoles) {
  const QuantizedMesh m = quantized(icosphere(5), 16);
  for (double tau : {0.1, 0.2, 0.3, 0.5}) {
    SCOPED_TRACE("tau " + std::to_string(tau));
    auto r = buildReliefs(m, {}, {.tau = tau});
    ASSERT_TRUE(r.isOk()) << r.status().toString();
    expectValidLayout(m, *r, tau);
    expectClosedManifold(r->triangles);
    uint32_t count = 0;
    const std::vector<uint32_t> component = reliefComponents(*r, &count);
    EXPECT_EQ(count, 6u);
    // Each relief holds the pole of its vector, and every piece's centroid is nearer its relief's pole than the
    // opposite hemisphere (the boundaries sit near the cube's diagonals, where two or three axes tie).
    const Vec3d centre{32767.5, 32767.5, 32767.5};
    std::set<int> reliefs;
    for (size_t i = 0; i < r->triangles.size(); ++i) {
      const Triangle& t = r->triangles[i];
      const Vec3d c =
          vsub(vmul(vadd(vadd(r->positions[t[0]], r->positions[t[1]]), r->positions[t[2]]), 1.0 / 3), centre);
      const Vec3d unit = vmul(c, 1 / vlen(c));
      double most = 0;
      for (int k = 0; k < kReliefCount; ++k) most = std::max(most, alongRelief(unit, k));
      EXPECT_GT(alongRelief(unit, r->relief[i]), most - 0.35) << "piece " << i;
      reliefs.insert(r->relief[i]);
    }
    EXPECT_EQ(reliefs.size(), 6u);
  }
}

TEST(Relief, TorusReliefsAreHeightFieldsOnAClosedManifold) {
  const QuantizedMesh m = quantized(torus(96, 48, 1.0, 0.35), 14);
  auto r = buildReliefs(m, {}, {});
  ASSERT_TRUE(r.isOk()) << r.status().toString();
  expectValidLayout(m, *r, 0.2);
  expectClosedManifold(r->triangles);
  uint32_t count = 0;
  reliefComponents(*r, &count);
  // +z and -z are annuli (one each); +-x and +-y each come as an outer and an inner part.
  EXPECT_GE(count, 6u);
  EXPECT_LE(count, 12u);
  EXPECT_GT(r->split_triangles, 0u);
}

// The paper's reason for the distance fields: choosing each triangle's relief by its normal alone gives jagged
// boundaries and many small reliefs on a rough surface. On a noisy sphere the distance fields give few reliefs and
// a shorter boundary; smaller tau gives smoother boundaries (Fig. 2).
TEST(Relief, SmootherAndFewerThanTheNaiveChoiceOnARoughSphere) {
  Mesh sphere = icosphere(5);
  std::mt19937 rng(7);
  std::normal_distribution<double> noise(0, 0.005);  // about an eighth of an edge
  for (Vec3d& p : sphere.positions) p = vmul(p, 1 + noise(rng));
  const QuantizedMesh m = quantized(sphere, 16);

  ReliefLayout naive;
  for (const Vec3u& q : m.positions) naive.positions.push_back({double(q[0]), double(q[1]), double(q[2])});
  for (uint32_t t = 0; t < m.triangles.size(); ++t) {
    const Vec3d n = normalOf(naive.positions, m.triangles[t]);
    int best = 0;
    for (int k = 1; k < kReliefCount; ++k)
      if (alongRelief(n, k) > alongRelief(n, best)) best = k;
    naive.triangles.push_back(m.triangles[t]);
    naive.relief.push_back(uint8_t(best));
    naive.source.push_back(t);
  }
  uint32_t naive_count = 0;
  reliefComponents(naive, &naive_count);
  const double naive_length = boundaryLength(naive.positions, naive.triangles, naive.relief);

  double previous_length = 0;
  for (double tau : {0.1, 0.2, 0.3, 0.5}) {
    auto r = buildReliefs(m, {}, {.tau = tau});
    ASSERT_TRUE(r.isOk());
    expectValidLayout(m, *r, tau);
    expectClosedManifold(r->triangles);
    uint32_t count = 0;
    reliefComponents(*r, &count);
    const double length = boundaryLength(r->positions, r->triangles, r->relief);
    std::printf("tau %.1f: %u reliefs, boundary %.0f (naive: %u reliefs, boundary %.0f); %llu split, %llu refaced\n",
                tau, count, length, naive_count, naive_length, static_cast<unsigned long long>(r->split_triangles),
                static_cast<unsigned long long>(r->refaced_triangles));
    if (tau <= 0.3) {
      EXPECT_LT(count, naive_count / 4);
      EXPECT_LT(length, 0.5 * naive_length);
    }
    if (previous_length > 0) {
      EXPECT_GT(length, previous_length) << "tau " << tau;
    }
    previous_length = length;
  }
}

// A plane facing (1, 1, 1): no triangle is in any A_v of the three axes it faces, so all their distances are
// infinite and tie; the tie goes to the vector the vertices face most, the same everywhere: one relief, no split.
TEST(Relief, TiesGoToTheVectorTheSurfaceFaces) {
  QuantizedMesh m;
  for (uint32_t i = 0; i < 8; ++i)
    for (uint32_t j = 0; j < 8; ++j)
      m.positions.push_back({100 + 10 * i, 100 + 10 * j + 7, 100 + 2 * 80 - 10 * i - 10 * j});
  for (uint32_t i = 0; i + 1 < 8; ++i)
    for (uint32_t j = 0; j + 1 < 8; ++j) {
      const uint32_t a = i * 8 + j;
      m.triangles.push_back({a, a + 8, a + 9});
      m.triangles.push_back({a, a + 9, a + 1});
    }
  auto r = buildReliefs(m, {}, {});
  ASSERT_TRUE(r.isOk());
  expectValidLayout(m, *r, 0.2);
  EXPECT_EQ(r->split_triangles, 0u);
  EXPECT_EQ(r->triangles.size(), m.triangles.size());
  for (uint8_t relief : r->relief) EXPECT_EQ(relief, r->relief[0]);
}

// A tile's border: the rim of a hemisphere (edges used by one triangle) with its vertices locked. The rim crosses
// several reliefs' boundaries, yet every rim edge stays an edge of the refinement (a boundary meets the rim at a
// vertex).
TEST(Relief, TileBorderEdgesAreNeverCut) {
  // The cap above a horizontal plane: its rim runs through the four side reliefs.
  const testing::LockedCap cap = testing::lockedCap(quantized(icosphere(4), 14), 14, 100);
  const QuantizedMesh& half = cap.mesh;
  const std::vector<uint8_t>& locked = cap.locked;
  const size_t rim = cap.rim.size();
  ASSERT_GT(rim, 20u);
  auto wrong = buildReliefs(half, std::vector<uint8_t>(3, 1), {});
  ASSERT_FALSE(wrong.isOk());
  EXPECT_EQ(wrong.status().code(), ErrorCode::kInvalidArgument);
  for (bool lock : {false, true}) {
    auto r = buildReliefs(half, lock ? std::span<const uint8_t>(locked) : std::span<const uint8_t>(), {.tau = 0.2});
    ASSERT_TRUE(r.isOk()) << r.status().toString();
    expectValidLayout(half, *r, 0.2);
    std::set<std::pair<uint32_t, uint32_t>> edges;
    for (const Triangle& t : r->triangles)
      for (int k = 0; k < 3; ++k) edges.insert(std::minmax(t[size_t(k)], t[size_t((k + 1) % 3)]));
    size_t kept = 0;
    for (const auto& e : cap.rim) kept += edges.count(e);
    if (lock) {
      EXPECT_EQ(kept, rim);
    } else {
      EXPECT_LT(kept, rim);  // unlocked, the rim is cut where reliefs meet it
    }
    std::set<int> reliefs(r->relief.begin(), r->relief.end());
    EXPECT_GE(reliefs.size(), 5u);
  }
}

TEST(Relief, UglyInputsComeThrough) {
  {  // empty, and stray vertices only
    QuantizedMesh empty;
    auto r = buildReliefs(empty, {}, {});
    ASSERT_TRUE(r.isOk());
    EXPECT_TRUE(r->triangles.empty());
    QuantizedMesh stray;
    stray.positions = {{1, 2, 3}, {4, 5, 6}};
    r = buildReliefs(stray, {}, {});
    ASSERT_TRUE(r.isOk());
    EXPECT_EQ(r->positions.size(), 2u);
  }
  // A sphere with the ugly parts added: zero-area triangles (collinear and coincident corners), a triangle that
  // repeats a vertex, a fin of three triangles on one edge (non-manifold), a soup of loose triangles, stray
  // vertices, and corners near the top of a 24-bit grid.
  QuantizedMesh m = quantized(icosphere(3), 24);
  const uint32_t n = uint32_t(m.positions.size());
  const Vec3u far{(1u << 24) - 1, (1u << 24) - 2, 3};
  m.positions.push_back(far);                                                        // n: stray
  m.positions.push_back({m.positions[0][0], m.positions[0][1], m.positions[0][2]});  // n+1: coincident with 0
  const Vec3u a = m.positions[m.triangles[0][0]], b = m.positions[m.triangles[0][1]];
  m.positions.push_back({(a[0] + b[0]) / 2, (a[1] + b[1]) / 2, (a[2] + b[2]) / 2});  // n+2: near the edge's middle
  const Triangle t0 = m.triangles[0];
  m.triangles.push_back({t0[0], t0[1], n + 2});  // (near) zero area on an edge
  m.triangles.push_back({0, n + 1, t0[1]});      // coincident corners
  m.triangles.push_back({t0[0], t0[0], t0[2]});  // repeats a vertex
  m.positions.push_back({a[0], a[1], a[2] + 50000});
  m.triangles.push_back({t0[0], t0[1], n + 3});  // a third triangle on edge t0[0]-t0[1]
  for (uint32_t k = 0; k < 5; ++k) {             // a soup near the far corner
    const uint32_t s = uint32_t(m.positions.size());
    m.positions.push_back({far[0] - 1000 * k, far[1], far[2] + 1000 * k});
    m.positions.push_back({far[0] - 1000 * k, far[1] - 900, far[2] + 1000 * k});
    m.positions.push_back({far[0] - 1000 * k - 800, far[1], far[2] + 1000 * k + 300});
    m.triangles.push_back({s, s + 1, s + 2});
  }
  auto r = buildReliefs(m, {}, {});
  ASSERT_TRUE(r.isOk()) << r.status().toString();
  expectValidLayout(m, *r, 0.2);
}

}  // namespace
}  // namespace scanpress
