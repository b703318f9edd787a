// The shape-preserving simplifier (engine/simplify/simplify.h) on analytic and hand-made meshes: the paper's
// weights, locks and border chains, no normal flips, the passes' independence, stop conditions, ugly inputs.
// Every result is replayed independently (simplify_util.h).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <map>
#include <set>

#include "engine/shapes.h"
#include "engine/simplify/simplify.h"
#include "engine/stages/stage.h"
#include "simplify_util.h"

namespace scanpress {
namespace {

using testing::expectValidSimplification;

// A deterministic hash in [0, 1).
double noise(uint32_t i, uint32_t j) {
  uint32_t h = i * 73856093u ^ j * 19349663u;
  h ^= h >> 13, h *= 0x5bd1e995u, h ^= h >> 15;
  return (h & 0xFFFF) / 65536.0;
}

// An n x n grid of squares (spacing 64 cells) in z = 1000 + bumps, split into triangles facing +z; open boundary
// on the square [0, 64n]^2 (+ offset).
QuantizedMesh bumpyGrid(uint32_t n, double bump = 8) {
  QuantizedMesh m;
  const uint32_t off = 100;
  for (uint32_t j = 0; j <= n; ++j)
    for (uint32_t i = 0; i <= n; ++i) {
      const double z = 1000 + bump * (std::sin(i * 0.3) * std::cos(j * 0.2) + 0.3 * noise(i, j));
      m.positions.push_back({off + 64 * i, off + 64 * j, uint32_t(std::lround(z))});
    }
  auto id = [n](uint32_t i, uint32_t j) { return j * (n + 1) + i; };
  for (uint32_t j = 0; j < n; ++j)
    for (uint32_t i = 0; i < n; ++i) {
      m.triangles.push_back({id(i, j), id(i + 1, j), id(i + 1, j + 1)});
      m.triangles.push_back({id(i, j), id(i + 1, j + 1), id(i, j + 1)});
    }
  return m;
}

QuantizedMesh quantizedSphere(int levels, double radius = 20000) {
  const Mesh s = icosphere(levels);
  QuantizedMesh m;
  for (const auto& p : s.positions)
    m.positions.push_back({uint32_t(std::lround(32768 + radius * p[0])), uint32_t(std::lround(32768 + radius * p[1])),
                           uint32_t(std::lround(32768 + radius * p[2]))});
  m.triangles = s.triangles;
  return m;
}

Simplification run(const QuantizedMesh& m, std::span<const uint8_t> locked, const SimplifyOptions& o) {
  auto r = simplify(m, locked, o);
  EXPECT_TRUE(r.isOk()) << r.status().toString();
  if (!r.isOk()) return {};
  return std::move(*r);
}

// Undirected edges of a mesh with one triangle (its boundary edges).
std::vector<std::pair<uint32_t, uint32_t>> openEdges(const QuantizedMesh& m) {
  std::vector<std::pair<uint32_t, uint32_t>> out;
  for (const auto& [e, n] : testing::edgeCounts(m))
    if (n == 1) out.push_back(e);
  return out;
}

TEST(Simplify, SphereReachesTheTargetWithoutFlipsAndReplaysExactly) {
  const QuantizedMesh m = quantizedSphere(5);  // 20480 triangles
  SimplifyOptions o;
  o.target_faces = m.triangles.size() / 10;
  const Simplification s = run(m, {}, o);
  expectValidSimplification(m, {}, s);
  EXPECT_LE(s.mesh.triangles.size(), o.target_faces);
  EXPECT_GE(s.mesh.triangles.size(), o.target_faces - 2);
  EXPECT_GT(s.pass_ends.size(), 3u);
  // Every output triangle faces outwards, as every input triangle does.
  for (const auto& t : s.mesh.triangles) {
    double p[3][3];
    for (int c = 0; c < 3; ++c)
      for (int a = 0; a < 3; ++a) p[c][a] = double(s.mesh.positions[t[c]][a]) - 32768;
    const double u[3] = {p[1][0] - p[0][0], p[1][1] - p[0][1], p[1][2] - p[0][2]};
    const double v[3] = {p[2][0] - p[0][0], p[2][1] - p[0][1], p[2][2] - p[0][2]};
    const double n[3] = {u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]};
    const double centroid_dot = n[0] * (p[0][0] + p[1][0] + p[2][0]) + n[1] * (p[0][1] + p[1][1] + p[2][1]) +
                                n[2] * (p[0][2] + p[1][2] + p[2][2]);
    EXPECT_GT(centroid_dot, 0) << "a triangle faces inwards";
  }
  // The surface stays on the sphere: every vertex within a few percent of the radius (the error estimate agrees).
  const auto used = testing::usedVertices(s.mesh);
  for (size_t v = 0; v < used.size(); ++v) {
    if (!used[v]) continue;
    double r2 = 0;
    for (int a = 0; a < 3; ++a) r2 += std::pow(double(s.mesh.positions[v][a]) - 32768, 2);
    EXPECT_NEAR(std::sqrt(r2), 20000, 400);
  }
  EXPECT_GT(s.pass_errors.back(), 0);
  EXPECT_TRUE(std::is_sorted(s.pass_errors.begin(), s.pass_errors.end()));
  EXPECT_TRUE(std::is_sorted(s.pass_faces.rbegin(), s.pass_faces.rend()));
  // Deterministic.
  const Simplification again = run(m, {}, o);
  EXPECT_EQ(again.mesh.triangles, s.mesh.triangles);
  EXPECT_EQ(again.pass_ends, s.pass_ends);
}

TEST(Simplify, MaxErrorBoundsEveryCollapse) {
  const QuantizedMesh m = quantizedSphere(5);
  SimplifyOptions o;
  o.target_faces = m.triangles.size() / 10;
  const float reached = run(m, {}, o).pass_errors.back();
  // Half the error that 10% needed: every collapse within it, and the mesh stops above 10%.
  o.target_faces = 0;
  o.max_error = reached / 2;
  const Simplification s = run(m, {}, o);
  expectValidSimplification(m, {}, s);
  ASSERT_FALSE(s.collapses.empty());
  EXPECT_GT(s.mesh.triangles.size(), m.triangles.size() / 10);
  for (const auto& c : s.collapses) EXPECT_LE(c.error, o.max_error);
  // A tighter bound stops earlier.
  o.max_error = reached / 8;
  const Simplification t = run(m, {}, o);
  expectValidSimplification(m, {}, t);
  EXPECT_GT(t.mesh.triangles.size(), s.mesh.triangles.size());
  for (const auto& c : t.collapses) EXPECT_LE(c.error, o.max_error);
  // Zero: only exact collapses.
  o.max_error = 0;
  for (const auto& c : run(m, {}, o).collapses) EXPECT_EQ(c.error, 0.0f);
}

TEST(Simplify, PassFractionBoundsEachPass) {
  const QuantizedMesh m = quantizedSphere(4);
  SimplifyOptions o;
  o.target_faces = 200;
  o.pass_fraction = 0.05;
  const Simplification s = run(m, {}, o);
  expectValidSimplification(m, {}, s);
  uint64_t faces = m.triangles.size();
  for (size_t p = 0; p < s.pass_faces.size(); ++p) {
    // A collapse removes at most two faces here (manifold), so a pass overshoots its share by at most one collapse.
    EXPECT_LE(faces - s.pass_faces[p], uint64_t(std::ceil(0.05 * faces)) + 1) << "pass " << p;
    faces = s.pass_faces[p];
  }
  EXPECT_LE(s.mesh.triangles.size(), 200u);
}

TEST(Simplify, BoundaryKeepsItsOutline) {
  const uint32_t n = 40;
  const QuantizedMesh m = bumpyGrid(n);
  const uint32_t lo = 100, hi = 100 + 64 * n;
  SimplifyOptions o;
  o.target_faces = m.triangles.size() / 10;
  const Simplification s = run(m, {}, o);
  expectValidSimplification(m, {}, s);
  EXPECT_LE(s.mesh.triangles.size(), o.target_faces);
  // Every boundary vertex of the result lies on the square outline, the corners are kept, and boundary edges run
  // along one side (never across a corner or inward).
  auto on_side = [&](const Vec3u& p) { return p[0] == lo || p[0] == hi || p[1] == lo || p[1] == hi; };
  for (const auto& [a, b] : openEdges(s.mesh)) {
    const Vec3u &pa = s.mesh.positions[a], &pb = s.mesh.positions[b];
    EXPECT_TRUE(on_side(pa) && on_side(pb));
    EXPECT_TRUE((pa[0] == pb[0] && (pa[0] == lo || pa[0] == hi)) || (pa[1] == pb[1] && (pa[1] == lo || pa[1] == hi)))
        << "boundary edge leaves the outline";
  }
  std::set<std::pair<uint32_t, uint32_t>> corners;
  for (const auto& [a, b] : openEdges(s.mesh))
    for (uint32_t v : {a, b})
      if ((s.mesh.positions[v][0] == lo || s.mesh.positions[v][0] == hi) &&
          (s.mesh.positions[v][1] == lo || s.mesh.positions[v][1] == hi))
        corners.insert({s.mesh.positions[v][0], s.mesh.positions[v][1]});
  EXPECT_EQ(corners.size(), 4u);
  // No boundary vertex was pulled inward: a removed input-boundary vertex went along the boundary.
  std::vector<uint8_t> boundary(m.positions.size(), 0);
  for (const auto& [a, b] : openEdges(m)) boundary[a] = boundary[b] = 1;
  for (const auto& c : s.collapses)
    if (boundary[c.removed]) {
      EXPECT_TRUE(on_side(c.position));
    }
}

// A bumpy plane with a bumpy fin standing on its middle row: the row's edges have three triangles (complex).
QuantizedMesh finMesh(uint32_t n, std::vector<uint8_t>* junction) {
  QuantizedMesh m = bumpyGrid(n, 6);
  const uint32_t row = n / 2, base = uint32_t(m.positions.size());
  auto id = [n](uint32_t i, uint32_t j) { return j * (n + 1) + i; };
  const uint32_t h = n / 3;
  for (uint32_t k = 1; k <= h; ++k)
    for (uint32_t i = 0; i <= n; ++i) {
      const Vec3u p = m.positions[id(i, row)];
      m.positions.push_back({p[0], uint32_t(p[1] + 8 * std::sin(i * 0.4 + k) + 4 * noise(i, k + 100)), p[2] + 64 * k});
    }
  auto fid = [&](uint32_t i, uint32_t k) { return k == 0 ? id(i, row) : base + (k - 1) * (n + 1) + i; };
  for (uint32_t k = 0; k < h; ++k)
    for (uint32_t i = 0; i < n; ++i) {
      m.triangles.push_back({fid(i, k), fid(i + 1, k), fid(i + 1, k + 1)});
      m.triangles.push_back({fid(i, k), fid(i + 1, k + 1), fid(i, k + 1)});
    }
  junction->assign(m.positions.size(), 0);
  for (uint32_t i = 0; i <= n; ++i) (*junction)[id(i, row)] = 1;
  return m;
}

TEST(Simplify, ComplexEdgesSurviveLongerThanWithPlainWeights) {
  std::vector<uint8_t> junction;
  const QuantizedMesh m = finMesh(30, &junction);
  size_t complex_edges = 0;
  for (const auto& [e, c] : testing::edgeCounts(m)) complex_edges += c > 2;
  ASSERT_EQ(complex_edges, 30u);
  auto surviving = [&](SimplifyWeights w, size_t target) {
    SimplifyOptions o;
    o.weights = w;
    o.target_faces = target;
    const Simplification s = run(m, {}, o);
    expectValidSimplification(m, {}, s);
    size_t kept = 0;
    for (const auto& [e, c] : testing::edgeCounts(s.mesh)) kept += c > 2;
    return kept;
  };
  for (size_t target : {m.triangles.size() / 2, m.triangles.size() / 5}) {
    const size_t paper = surviving(SimplifyWeights::kShapePreserving, target);
    const size_t plain = surviving(SimplifyWeights::kPlain, target);
    EXPECT_GT(paper, plain) << "target " << target;
    EXPECT_GT(paper, 0u);
  }
  // With the paper's weights a junction vertex never leaves the junction line.
  SimplifyOptions o;
  o.target_faces = m.triangles.size() / 5;
  for (const auto& c : run(m, {}, o).collapses)
    if (junction[c.removed]) {
      EXPECT_TRUE(junction[c.kept]);
    }
}

TEST(Simplify, LockedVerticesAndBorderChainsStay) {
  const uint32_t n = 30;
  const QuantizedMesh m = bumpyGrid(n);
  // Lock the left column and the top row (a tile's border), and a diagonal line of interior vertices.
  std::vector<uint8_t> locked(m.positions.size(), 0);
  for (uint32_t j = 0; j <= n; ++j) locked[j * (n + 1)] = 1;
  for (uint32_t i = 0; i <= n; ++i) locked[n * (n + 1) + i] = 1;
  for (uint32_t k = 5; k < 20; ++k) locked[k * (n + 1) + k] = 1;
  SimplifyOptions o;
  o.target_faces = 100;
  for (SimplifyWeights w : {SimplifyWeights::kShapePreserving, SimplifyWeights::kPlain}) {
    o.weights = w;
    const Simplification s = run(m, locked, o);
    expectValidSimplification(m, locked, s);
    EXPECT_LT(s.mesh.triangles.size(), m.triangles.size() / 4);
    TileContext ctx;
    ctx.bits = 16;
    const Status st = checkBorderContract(ctx, TileView{m, locked}, TileView{s.mesh, locked}, true);
    EXPECT_TRUE(st.isOk()) << st.toString();
    for (const auto& c : s.collapses) {
      EXPECT_FALSE(locked[c.removed]);
      if (locked[c.kept]) {
        EXPECT_EQ(c.position, m.positions[c.kept]);
      }
    }
  }
  // Everything locked: nothing moves.
  std::vector<uint8_t> all(m.positions.size(), 1);
  const Simplification s = run(m, all, o);
  EXPECT_TRUE(s.collapses.empty());
  EXPECT_EQ(s.mesh.triangles, m.triangles);
}

TEST(Simplify, UglyInputsKeepTheContracts) {
  SimplifyOptions o;
  o.target_faces = 1;
  // Empty, point cloud, isolated vertices.
  {
    const QuantizedMesh empty;
    const Simplification s = run(empty, {}, o);
    EXPECT_TRUE(s.collapses.empty());
    EXPECT_TRUE(s.pass_ends.empty());
    QuantizedMesh cloud;
    cloud.positions = {{1, 2, 3}, {1, 2, 3}, {5, 5, 5}};
    const Simplification c = run(cloud, {}, o);
    EXPECT_TRUE(c.collapses.empty());
    EXPECT_EQ(c.mesh.positions, cloud.positions);
  }
  // A sphere with duplicate vertices at one position (a second copy of some vertices, used by no triangle, and a
  // seam: some triangles use the copy), isolated vertices and a degenerate triangle (repeated index) and a
  // zero-area one (two corners in one cell).
  {
    QuantizedMesh m = quantizedSphere(3);
    const uint32_t v0 = m.triangles[0][0];
    m.positions.push_back(m.positions[v0]);  // duplicate position, used by the triangles that follow
    const uint32_t dup = uint32_t(m.positions.size() - 1);
    for (size_t f = 1; f < m.triangles.size(); ++f)
      for (auto& v : m.triangles[f])
        if (v == v0 && f % 2 == 0) v = dup;
    m.positions.push_back({7, 7, 7});  // isolated
    m.positions.push_back({100, 100, 100});
    const uint32_t iso = uint32_t(m.positions.size() - 1);
    m.triangles.push_back({iso, iso, m.triangles[5][0]});  // repeats a vertex
    m.positions.push_back(m.positions[m.triangles[9][1]]);
    m.triangles.push_back({m.triangles[9][0], m.triangles[9][1], uint32_t(m.positions.size() - 1)});  // zero area
    const std::vector<Triangle> degenerate = {m.triangles[m.triangles.size() - 2], m.triangles.back()};
    const Simplification s = run(m, {}, o);
    expectValidSimplification(m, {}, s);
    EXPECT_LT(s.mesh.triangles.size(), m.triangles.size() / 4);
    for (const auto& t : degenerate)
      EXPECT_NE(std::find(s.mesh.triangles.begin(), s.mesh.triangles.end(), t), s.mesh.triangles.end())
          << "a degenerate input triangle is kept as it is";
  }
  // A non-manifold fan: five triangles on one edge, each with a small strip beyond it.
  {
    QuantizedMesh m;
    m.positions = {{2000, 2000, 1000}, {2000, 2000, 3000}};
    for (int k = 0; k < 5; ++k) {
      const double a = k * 2 * M_PI / 5;
      for (int r = 1; r <= 3; ++r)  // (around the center, far enough from 0 that no coordinate goes negative)
        m.positions.push_back({uint32_t(2000 + 500 * r * std::cos(a)), uint32_t(2000 + 500 * r * std::sin(a)),
                               uint32_t(2000 + 37 * r * (k + 1))});
      const uint32_t b = 2 + 3 * k;
      m.triangles.push_back({0, 1, b});
      m.triangles.push_back({b, 1, b + 1});
      m.triangles.push_back({b, b + 1, b + 2});
      m.triangles.push_back({0, b, b + 2});
    }
    for (SimplifyWeights w : {SimplifyWeights::kShapePreserving, SimplifyWeights::kPlain}) {
      o.weights = w;
      const Simplification s = run(m, {}, o);
      expectValidSimplification(m, {}, s);
      EXPECT_FALSE(s.collapses.empty());
    }
  }
  // A single triangle and two triangles: nothing legal collapses them into nothing.
  {
    QuantizedMesh m;
    m.positions = {{0, 0, 0}, {100, 0, 0}, {0, 100, 0}, {100, 100, 5}};
    m.triangles = {{0, 1, 2}};
    Simplification s = run(m, {}, o);
    expectValidSimplification(m, {}, s);
    EXPECT_EQ(s.mesh.triangles.size(), 1u);
    m.triangles.push_back({1, 3, 2});
    s = run(m, {}, o);
    expectValidSimplification(m, {}, s);
    EXPECT_GE(s.mesh.triangles.size(), 1u);
  }
  // Bad arguments.
  {
    QuantizedMesh m;
    m.positions = {{0, 0, 0}};
    m.triangles = {{0, 0, 1}};
    EXPECT_EQ(simplify(m, {}, o).status().code(), ErrorCode::kInvalidArgument);
    m.triangles.clear();
    const std::vector<uint8_t> flags = {1, 1};
    EXPECT_EQ(simplify(m, flags, o).status().code(), ErrorCode::kInvalidArgument);
    SimplifyOptions bad;
    bad.pass_fraction = 0;
    EXPECT_EQ(simplify(m, {}, bad).status().code(), ErrorCode::kInvalidArgument);
  }
}

// Random damage on a sphere: triangles removed (holes, slivers of surface, isolated pieces), random triangles
// added between random vertices (complex edges, non-manifold vertices, flipped and sliver triangles, duplicates)
// and random locks; every seed and both weight sets keep the contracts down to one face.
TEST(Simplify, RandomlyDamagedMeshesKeepTheContracts) {
  const QuantizedMesh sphere = quantizedSphere(3);  // 1280 triangles, 642 vertices
  for (uint32_t seed = 1; seed <= 12; ++seed) {
    QuantizedMesh m;
    m.positions = sphere.positions;
    for (size_t f = 0; f < sphere.triangles.size(); ++f)
      if (noise(seed, uint32_t(f)) > 0.15 * (seed % 4)) m.triangles.push_back(sphere.triangles[f]);
    const uint32_t n = uint32_t(m.positions.size());
    for (uint32_t k = 0; k < 4 * seed; ++k) {
      const uint32_t a = uint32_t(noise(seed + 100, k) * n), b = uint32_t(noise(seed + 200, k) * n),
                     c = uint32_t(noise(seed + 300, k) * n);
      if (k % 3 == 0) {
        m.triangles.push_back(m.triangles[k % m.triangles.size()]);  // a duplicate triangle
      } else {
        m.triangles.push_back({a, b, c});
      }
    }
    std::vector<uint8_t> locked(n, 0);
    if (seed % 2 == 0)
      for (uint32_t v = 0; v < n; ++v) locked[v] = noise(seed + 400, v) < 0.1 ? 1 : 0;
    for (SimplifyWeights w : {SimplifyWeights::kShapePreserving, SimplifyWeights::kPlain}) {
      SimplifyOptions o;
      o.weights = w;
      o.target_faces = 1;
      o.pass_fraction = 0.1 + 0.1 * (seed % 5);
      const Simplification s = run(m, locked, o);
      SCOPED_TRACE("seed " + std::to_string(seed));
      expectValidSimplification(m, locked, s);
      EXPECT_LT(s.mesh.triangles.size(), m.triangles.size() / 2);
      TileContext ctx;
      ctx.bits = 16;
      const Status st = checkBorderContract(ctx, TileView{m, locked}, TileView{s.mesh, locked}, true);
      EXPECT_TRUE(st.isOk()) << st.toString();
    }
  }
}

// Corner wedges (simplify.h): the sphere cut by two seams, the planes x = 0 and y = 0 through its center, into four
// sides (a triangle's side: the signs of its centroid's x and y); a vertex has one wedge per side its triangles lie
// on (four at the poles). Simplified to a tenth: every output corner names a wedge of its own vertex, every
// triangle's three wedges are of one side (no triangle across a seam), and the mesh is still valid and simplified.
// With one wedge per vertex (its own id) the rules bind nothing: the same collapses as without wedges.
TEST(Simplify, CornerWedgesKeepEachSideOnItsSide) {
  const QuantizedMesh m = quantizedSphere(4);
  auto sideOf = [&](const Triangle& t) {
    int64_t x = 0, y = 0;
    for (uint32_t v : t) x += int64_t(m.positions[v][0]) - 32768, y += int64_t(m.positions[v][1]) - 32768;
    return (x < 0 ? 0 : 1) + (y < 0 ? 0 : 2);
  };
  std::map<std::pair<uint32_t, int>, uint32_t> id;  // (vertex, side) -> wedge
  std::vector<uint32_t> wedge_vertex;
  std::vector<int> wedge_side;
  std::vector<uint32_t> corners;
  for (const Triangle& t : m.triangles) {
    const int side = sideOf(t);
    for (uint32_t v : t) {
      const auto [it, fresh] = id.try_emplace({v, side}, uint32_t(wedge_vertex.size()));
      if (fresh) wedge_vertex.push_back(v), wedge_side.push_back(side);
      corners.push_back(it->second);
    }
  }
  ASSERT_GT(wedge_vertex.size(), m.positions.size() + 60) << "the seams split vertices";
  SimplifyOptions o;
  o.target_faces = m.triangles.size() / 10;
  auto r = simplify(m, {}, o, corners);
  ASSERT_TRUE(r.isOk()) << r.status().toString();
  expectValidSimplification(m, {}, *r);
  EXPECT_LE(r->mesh.triangles.size(), m.triangles.size() / 5);
  ASSERT_EQ(r->corner_wedges.size(), 3 * r->mesh.triangles.size());
  size_t seam_triangles = 0;
  for (size_t f = 0; f < r->mesh.triangles.size(); ++f) {
    const Triangle& t = r->mesh.triangles[f];
    std::set<int> sides;
    for (int k = 0; k < 3; ++k) {
      const uint32_t w = r->corner_wedges[3 * f + size_t(k)];
      ASSERT_LT(w, wedge_vertex.size());
      EXPECT_EQ(wedge_vertex[w], t[size_t(k)]) << "a corner names another vertex's wedge";
      sides.insert(wedge_side[w]);
    }
    EXPECT_EQ(sides.size(), 1u) << "triangle " << f << " lies across a seam";
    std::set<int> geometric;  // where the triangle lies, by its corners' wedges having more than one side
    for (uint32_t v : t) {
      int n = 0;
      for (int sd = 0; sd < 4; ++sd) n += id.count({v, sd});
      geometric.insert(n);
    }
    seam_triangles += *geometric.rbegin() > 1;
  }
  EXPECT_GT(seam_triangles, 20u) << "triangles along the seams remain";
  // One wedge per vertex: the same simplification.
  std::vector<uint32_t> own;
  for (const Triangle& t : m.triangles) own.insert(own.end(), t.begin(), t.end());
  auto with = simplify(m, {}, o, own);
  auto without = simplify(m, {}, o);
  ASSERT_TRUE(with.isOk() && without.isOk());
  ASSERT_EQ(with->collapses.size(), without->collapses.size());
  for (size_t i = 0; i < with->collapses.size(); ++i) {
    EXPECT_EQ(with->collapses[i].kept, without->collapses[i].kept) << i;
    EXPECT_EQ(with->collapses[i].removed, without->collapses[i].removed) << i;
  }
  EXPECT_EQ(with->corner_wedges, [&] {
    std::vector<uint32_t> c;
    for (const Triangle& t : without->mesh.triangles) c.insert(c.end(), t.begin(), t.end());
    return c;
  }());
  // Corner wedges of the wrong count are refused.
  EXPECT_EQ(simplify(m, {}, o, std::span(own).first(5)).status().code(), ErrorCode::kInvalidArgument);
}

}  // namespace
}  // namespace scanpress
