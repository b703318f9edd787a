// Geometry stages and the border contract (engine/stages): the contract check against hand-made violations, and
// the smooth stage against an analytic shape (a noisy sphere gets closer to the sphere; locked vertices and the
// connectivity stay).
#include <gtest/gtest.h>

#include <cmath>
#include <map>
#include <random>

#include "engine/geometry.h"
#include "engine/octahedral.h"
#include "engine/quantize.h"
#include "engine/shapes.h"
#include "engine/stages/stage.h"

namespace scanpress {
namespace {

// Two triangles of a strip, 0-1 the shared edge; vertices 0, 1, 2 locked (0-2 and 1-2 are border edges of
// triangle 0, 0-1 is interior).
QuantizedMesh strip() {
  QuantizedMesh m;
  m.positions = {{10, 10, 10}, {20, 10, 10}, {15, 20, 10}, {15, 0, 10}};
  m.triangles = {{0, 1, 2}, {1, 0, 3}};
  return m;
}

TEST(BorderContract, IdentityPassesAndEveryKindOfViolationIsNamed) {
  const TileContext ctx{8, {}};
  const QuantizedMesh m = strip();
  const std::vector<uint8_t> locked = {1, 1, 1, 0};
  const TileView before{m, locked};
  EXPECT_TRUE(checkBorderContract(ctx, before, before, true).isOk());

  // Unlocked vertex moved: fine.
  QuantizedMesh moved = m;
  moved.positions[3] = {15, 1, 10};
  EXPECT_TRUE(checkBorderContract(ctx, before, TileView{moved, locked}, true).isOk());
  // Locked vertex moved.
  QuantizedMesh bad = m;
  bad.positions[2] = {15, 21, 10};
  Status s = checkBorderContract(ctx, before, TileView{bad, locked}, true);
  EXPECT_EQ(s.code(), ErrorCode::kInternal);
  EXPECT_NE(s.message().find("locked vertex at (15, 20, 10)"), std::string::npos) << s.toString();
  // Locked vertex unlocked.
  const std::vector<uint8_t> unlocked = {1, 1, 0, 0};
  EXPECT_FALSE(checkBorderContract(ctx, before, TileView{m, unlocked}, true).isOk());
  // Border edge removed: triangle 0 dropped (its vertex 2 stays, isolated and locked).
  QuantizedMesh dropped = m;
  dropped.triangles = {{1, 0, 3}};
  s = checkBorderContract(ctx, before, TileView{dropped, locked}, true);
  EXPECT_NE(s.message().find("border edge"), std::string::npos) << s.toString();
  // The interior edge 0-1 may go (triangle 1 dropped: 0-1 is still an edge of triangle 0).
  QuantizedMesh interior = m;
  interior.triangles = {{0, 1, 2}};
  EXPECT_TRUE(checkBorderContract(ctx, before, TileView{interior, std::vector<uint8_t>{1, 1, 1, 0}}, true).isOk());
  // Flags that do not match the vertices; a mesh off the grid (thorough only).
  EXPECT_FALSE(checkBorderContract(ctx, before, TileView{m, std::vector<uint8_t>{1, 1, 1}}, false).isOk());
  QuantizedMesh off = m;
  off.positions[3] = {300, 0, 10};
  EXPECT_FALSE(checkBorderContract(ctx, before, TileView{off, locked}, true).isOk());
  EXPECT_TRUE(checkBorderContract(ctx, before, TileView{off, locked}, false).isOk());
}

TEST(SmoothStage, OptionsAreChecked) {
  StageSpec spec;
  EXPECT_TRUE(validateStage(spec).isOk());
  spec.smooth.lambda = 0;
  EXPECT_EQ(validateStage(spec).code(), ErrorCode::kInvalidArgument);
  spec.smooth = {};
  spec.smooth.mu = -0.2;  // must be below -lambda
  EXPECT_NE(validateStage(spec).message().find("mu"), std::string::npos);
  spec.smooth = {};
  spec.smooth.iterations = -1;
  EXPECT_NE(validateStage(spec).message().find("iterations"), std::string::npos);
  EXPECT_EQ(findStage("smooth")->kind, StageKind::kSmooth);
  EXPECT_EQ(findStage("nope"), nullptr);
}

// A sphere of radius 0.45 in the unit cube at 14 bits (edges of ~150 cells), with +-6 cells of noise on every
// vertex: smoothing brings the vertices closer to the sphere, keeps the locked half exactly and the triangles as
// they were. (On a coarse sphere, edges of ~600 cells, Taubin's small low-pass gain inflates the sphere by ~0.2
// cells per iteration, as the paper's passband says it will: the test shape must be dense, as scans are.)
TEST(SmoothStage, DenoisesASphereAndKeepsTheContract) {
  Mesh sphere = icosphere(6);
  for (auto& p : sphere.positions)
    for (double& c : p) c = 0.5 + 0.45 * c;
  BoundingBox box;
  box.extend({0, 0, 0});
  box.extend({1, 1, 1});
  const Grid grid = *makeGrid(box, 14);
  QuantizedMesh q = *quantizeMesh(sphere, grid, {}, nullptr);
  std::mt19937 rng(5);
  std::uniform_int_distribution<int> noise(-6, 6);
  for (auto& p : q.positions)
    for (auto& c : p) c = uint32_t(int(c) + noise(rng));
  std::vector<uint8_t> locked(q.positions.size());
  for (size_t v = 0; v < locked.size(); ++v) locked[v] = q.positions[v][0] > (1u << 13) ? 1 : 0;
  auto rmsOffSphere = [&](const QuantizedMesh& m, bool unlocked_only) {
    double sum = 0;
    size_t n = 0;
    for (size_t v = 0; v < m.positions.size(); ++v) {
      if (unlocked_only && locked[v]) continue;
      const Vec3d p = grid.dequantize(m.positions[v]);
      const double r = std::sqrt((p[0] - .5) * (p[0] - .5) + (p[1] - .5) * (p[1] - .5) + (p[2] - .5) * (p[2] - .5));
      sum += (r - 0.45) * (r - 0.45);
      ++n;
    }
    return std::sqrt(sum / n);
  };
  const TileContext ctx{14, {}};
  const StageSpec spec;  // 10 iterations, lambda 0.33, mu -0.34
  auto out = runStage(ctx, TileView{q, locked}, spec, true);
  ASSERT_TRUE(out.isOk()) << out.status().toString();
  EXPECT_EQ(out->mesh.triangles, q.triangles);
  EXPECT_EQ(out->locked, locked);
  for (size_t v = 0; v < locked.size(); ++v) {
    if (locked[v]) {
      EXPECT_EQ(out->mesh.positions[v], q.positions[v]);
    }
  }
  const double before = rmsOffSphere(q, true), after = rmsOffSphere(out->mesh, true);
  RecordProperty("rms_before_cells", std::to_string(before / grid.cell));
  RecordProperty("rms_after_cells", std::to_string(after / grid.cell));
  EXPECT_LT(after, 0.6 * before) << before / grid.cell << " -> " << after / grid.cell << " cells";
  for (const auto& t : out->mesh.triangles) {
    const auto& p = out->mesh.positions;
    EXPECT_TRUE(p[t[0]] != p[t[1]] && p[t[1]] != p[t[2]] && p[t[0]] != p[t[2]]);
  }
  // Nothing locked: every vertex may move; still the same triangles, and the same at any call (pure).
  auto free = runStage(ctx, TileView{q, {}}, spec, true);
  ASSERT_TRUE(free.isOk());
  EXPECT_EQ(free->mesh.triangles, q.triangles);
  EXPECT_EQ(runStage(ctx, TileView{q, {}}, spec, true)->mesh.positions, free->mesh.positions);
  EXPECT_LT(rmsOffSphere(free->mesh, false), 0.6 * rmsOffSphere(q, false));
}

// The remesh stage on a tile (a cap of a sphere with its rim locked): the border contract holds (runStage checks
// it, thoroughly), the result is on the grid with no two corners in one cell, fewer vertices at a coarse
// grid, kept input vertices keep their normals and new ones point along the sphere's radius; the same at every
// call; colors are interpolated onto their levels; bad options are named.
TEST(RemeshStage, KeepsTheTileBorderAndCarriesNormalsAndColors) {
  Mesh sphere = icosphere(5);
  for (auto& p : sphere.positions) p = vadd(vmul(p, 0.45), {0.5, 0.5, 0.5});
  Mesh cap;
  cap.positions = sphere.positions;
  for (const Triangle& t : sphere.triangles)
    if (sphere.positions[t[0]][2] + sphere.positions[t[1]][2] + sphere.positions[t[2]][2] > 3 * 0.6)
      cap.triangles.push_back(t);
  for (const Vec3d& p : cap.positions) cap.normals.push_back({float(p[0] - .5), float(p[1] - .5), float(p[2] - .5)});
  BoundingBox box;
  box.lo = {0, 0, 0};
  box.hi = {1, 1, 1};
  const Grid grid = *makeGrid(box, 14);
  const AttributeLayout layout{12, 0};
  QuantizedMesh q = *quantizeMesh(cap, grid, layout, nullptr);
  std::map<std::pair<uint32_t, uint32_t>, int> uses;
  for (const auto& t : q.triangles)
    for (int k = 0; k < 3; ++k) ++uses[std::minmax(t[k], t[(k + 1) % 3])];
  std::vector<uint8_t> locked(q.positions.size(), 0);
  for (const auto& [e, n] : uses)
    if (n == 1) locked[e.first] = locked[e.second] = 1;
  StageSpec spec;
  spec.kind = StageKind::kRemesh;
  spec.remesh.grid = 0.02;  // 328 cells at 14 bits (the input's edges are about 240)
  EXPECT_EQ(remeshSpacing(spec.remesh, 14), 328u);
  const TileContext ctx{14, layout};
  auto out = runStage(ctx, TileView{q, locked}, spec, true);
  ASSERT_TRUE(out.isOk()) << out.status().toString();
  const QuantizedMesh& m = out->mesh;
  ASSERT_EQ(m.normals.size(), m.positions.size());
  EXPECT_LT(m.positions.size(), q.positions.size());
  std::map<Vec3u, size_t> input_at;
  for (size_t v = 0; v < q.positions.size(); ++v) input_at[q.positions[v]] = v;
  size_t kept = 0;
  for (size_t v = 0; v < m.positions.size(); ++v) {
    const auto it = input_at.find(m.positions[v]);
    if (it != input_at.end()) {
      EXPECT_EQ(m.normals[v], q.normals[it->second]);
      EXPECT_EQ(out->locked[v], locked[it->second]);
      ++kept;
      continue;
    }
    const Vec3d p = grid.dequantize(m.positions[v]);
    const Vec3d radial = vmul(vsub(p, {.5, .5, .5}), 1 / vlen(vsub(p, {.5, .5, .5})));
    const Vec3f n = decodeOctahedral(m.normals[v], 12);
    EXPECT_GT(radial[0] * n[0] + radial[1] * n[1] + radial[2] * n[2], std::cos(20 * 3.14159265 / 180)) << v;
  }
  EXPECT_GT(kept, 0u);
  for (const auto& t : m.triangles)
    EXPECT_TRUE(m.positions[t[0]] != m.positions[t[1]] && m.positions[t[1]] != m.positions[t[2]] &&
                m.positions[t[0]] != m.positions[t[2]]);
  auto again = runStage(ctx, TileView{q, locked}, spec, true);
  ASSERT_TRUE(again.isOk());
  EXPECT_EQ(again->mesh.positions, m.positions);
  EXPECT_EQ(again->mesh.triangles, m.triangles);

  // Colors, a gradient along x at 6 bits: kept vertices keep theirs, new ones get the gradient (the
  // interpolation of their input triangle's corners) on the 6-bit levels.
  AttributeLayout colored{12, 3};
  colored.color_bits = 6;
  QuantizedMesh qc = q;
  const auto gradient = [&](const Vec3u& p) {
    return quantizeColor(Rgba8{uint8_t(std::lround(255.0 * p[0] / 16383)), 100, 200, 255}, colored);
  };
  for (const Vec3u& p : qc.positions) qc.colors.push_back(gradient(p));
  auto colors = runStage(TileContext{14, colored}, TileView{qc, locked}, spec, true);
  ASSERT_TRUE(colors.isOk()) << colors.status().toString();
  ASSERT_EQ(colors->mesh.colors.size(), colors->mesh.positions.size());
  for (size_t v = 0; v < colors->mesh.positions.size(); ++v) {
    const Rgba8 c = colors->mesh.colors[v];
    EXPECT_EQ(quantizeColor(c, colored), c) << "off the 6-bit levels";
    const auto it = input_at.find(colors->mesh.positions[v]);
    if (it != input_at.end()) {
      EXPECT_EQ(c, qc.colors[it->second]);
    } else {
      EXPECT_NEAR(int(c[0]), int(gradient(colors->mesh.positions[v])[0]), 12);  // a triangle spans about 4 levels
      EXPECT_EQ(c[1], gradient({0, 0, 0})[1]);
    }
  }
  // Lock flags of the wrong size are refused; a grid too fine for the tile is a clean error, not an explosion.
  EXPECT_EQ(runStage(ctx, TileView{q, std::vector<uint8_t>(3, 1)}, spec, true).status().code(),
            ErrorCode::kInvalidArgument);
  StageSpec tiny = spec;
  tiny.remesh.grid = 1e-9;
  EXPECT_EQ(runStage(ctx, TileView{q, locked}, tiny, true).status().code(), ErrorCode::kLimitExceeded);
  StageSpec bad = spec;
  bad.remesh.grid = 0;
  EXPECT_NE(validateStage(bad).message().find("grid"), std::string::npos);
  bad = spec;
  bad.remesh.tau = 0.6;
  EXPECT_NE(validateStage(bad).message().find("tau"), std::string::npos);
}

}  // namespace
}  // namespace scanpress
