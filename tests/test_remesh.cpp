// Piecewise regular remeshing end to end (engine/remesh/remesh.h): reliefs resampled and merged. A closed sphere and
// a torus stay closed manifolds of the same genus; a tile's locked border keeps its vertices and edges; the
// boundary of an open mesh is the input's polyline; the surface stays within the expected distance of the input
// (analytic: a sphere's vertices on the sphere's chords); on real scans (../shared/data) the result is manifold
// where the input is, the boundary keeps its length and the area stays; tiled scans through the stage weld without
// cracks or non-manifold seams. Also ugly inputs and a grid too fine for the tile.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <map>
#include <set>

#include "engine/geometry.h"
#include "engine/quantize.h"
#include "engine/remesh/remesh.h"
#include "engine/shapes.h"
#include "engine/metro.h"
#include "engine/stages/stage.h"
#include "jobs/commands.h"
#include "jobs/mesh_io/mesh_reader.h"
#include "jobs/pipeline.h"
#include "jobs_util.h"

namespace scanpress {
namespace {

using testing::quantized;

// Directed edge counts: each directed edge at most once, and with `closed` its reverse present too.
struct EdgeCheck {
  size_t edges = 0, boundary = 0, non_manifold = 0;
  double boundary_length = 0;
};
EdgeCheck checkEdges(const std::vector<Vec3d>& p, const std::vector<Triangle>& triangles) {
  std::map<std::pair<uint32_t, uint32_t>, int> directed;
  for (const Triangle& t : triangles)
    for (int k = 0; k < 3; ++k) ++directed[{t[size_t(k)], t[size_t((k + 1) % 3)]}];
  std::map<std::pair<uint32_t, uint32_t>, int> undirected;
  for (const auto& [e, n] : directed) undirected[std::minmax(e.first, e.second)] += n;
  EdgeCheck c;
  c.edges = undirected.size();
  for (const auto& [e, n] : undirected) {
    if (n == 1) {
      ++c.boundary;
      c.boundary_length += vlen(vsub(p[e.first], p[e.second]));
    }
    if (n > 2) ++c.non_manifold;
  }
  for (const auto& [e, n] : directed)
    if (n > 1) ++c.non_manifold;
  return c;
}

size_t usedVertices(const std::vector<Triangle>& triangles) {
  std::set<uint32_t> used;
  for (const Triangle& t : triangles) used.insert(t.begin(), t.end());
  return used.size();
}

std::vector<Vec3d> doubles(const QuantizedMesh& m) {  // grid units
  std::vector<Vec3d> p;
  for (const Vec3u& q : m.positions) p.push_back({double(q[0]), double(q[1]), double(q[2])});
  return p;
}

double regularShare(const Remeshed& r) {
  size_t n = 0;
  for (uint8_t g : r.regular) n += g;
  return r.triangles.empty() ? 0 : double(n) / double(r.triangles.size());
}

TEST(Remesh, SphereStaysAClosedManifoldNearTheSphere) {
  const QuantizedMesh m = quantized(icosphere(4), 14);
  const double radius = (16383.0) / 2, centre = 16383.0 / 2;
  for (uint32_t spacing : {200u, 400u, 800u}) {
    SCOPED_TRACE("spacing " + std::to_string(spacing));
    auto r = remeshPiecewiseRegular(m, {}, {.tau = 0.2, .spacing = spacing});
    ASSERT_TRUE(r.isOk()) << r.status().toString();
    const EdgeCheck c = checkEdges(r->positions, r->triangles);
    EXPECT_EQ(c.boundary, 0u);
    EXPECT_EQ(c.non_manifold, 0u);
    // Euler characteristic 2 (genus 0).
    EXPECT_EQ(int64_t(usedVertices(r->triangles)) - int64_t(c.edges) + int64_t(r->triangles.size()), 2);
    // Every vertex lies on the input surface, whose triangles are inscribed in the sphere: not outside it (plus
    // quantization), and not deeper than a triangle's centre sags (side l below 0.08 radius: l^2 / 6).
    for (const Vec3d& p : r->positions) {
      const double d = vlen(vsub(p, {centre, centre, centre}));
      EXPECT_LE(d, radius + 2);
      EXPECT_GE(d, radius * (1 - 0.08 * 0.08 / 6) - 2);
    }
    EXPECT_GT(regularShare(*r), spacing <= 400 ? 0.6 : 0.3);
    std::printf("spacing %u: %zu triangles (%.1f%% regular), %u reliefs, %llu merge splits\n", spacing,
                r->triangles.size(), 100 * regularShare(*r), r->reliefs,
                static_cast<unsigned long long>(r->merge_splits));
  }
}

// The paper's collapse after merging: vertices off the grid (on relief boundaries) are collapsed onto grid vertices.
// Against the same remeshing without it: the vertices kept are a subset (a collapse moves none), most off-grid ones
// are gone, the mesh stays a closed genus-0 manifold and no regular triangle is lost.
TEST(Remesh, BoundaryVerticesCollapseOntoTheGrid) {
  const QuantizedMesh m = quantized(icosphere(5), 14);
  auto with = remeshPiecewiseRegular(m, {}, {.tau = 0.2, .spacing = 200});
  auto without = remeshPiecewiseRegular(m, {}, {.tau = 0.2, .spacing = 200, .collapse_onto_grid = false});
  ASSERT_TRUE(with.isOk() && without.isOk());
  EXPECT_GT(with->grid_collapses, 100u);
  const std::set<Vec3d> before(without->positions.begin(), without->positions.end());
  for (const Vec3d& p : with->positions) EXPECT_TRUE(before.count(p));
  EXPECT_EQ(with->positions.size() + with->grid_collapses, without->positions.size());
  const auto offGrid = [](const Remeshed& r) {
    std::vector<uint8_t> on(r.positions.size(), 0);
    for (size_t t = 0; t < r.triangles.size(); ++t)
      if (r.regular[t])
        for (uint32_t v : r.triangles[t]) on[v] = 1;
    return std::count(on.begin(), on.end(), 0);
  };
  EXPECT_LT(offGrid(*with), offGrid(*without) / 2);
  const EdgeCheck c = checkEdges(with->positions, with->triangles);
  EXPECT_EQ(c.boundary, 0u);
  EXPECT_EQ(c.non_manifold, 0u);
  EXPECT_EQ(int64_t(usedVertices(with->triangles)) - int64_t(c.edges) + int64_t(with->triangles.size()), 2);
  const auto regular = [](const Remeshed& r) { return std::count(r.regular.begin(), r.regular.end(), 1); };
  EXPECT_GE(regular(*with), regular(*without));
  std::printf("off-grid vertices %td -> %td, %llu collapses\n", offGrid(*without), offGrid(*with),
              static_cast<unsigned long long>(with->grid_collapses));
}

// The paper's area-reducing edge flips (§2.3): they move no vertex, touch no regular triangle, lower the area of
// the irregular band, and leave a closed manifold of the same genus whose triangles all face outwards (a sphere is
// convex: a fold would face inwards) and stay as near the sphere as the chords' sag allows.
TEST(Remesh, EdgeFlipsReduceTheIrregularBandsArea) {
  const QuantizedMesh m = quantized(icosphere(5), 14);
  auto with = remeshPiecewiseRegular(m, {}, {.tau = 0.2, .spacing = 200});
  auto without = remeshPiecewiseRegular(m, {}, {.tau = 0.2, .spacing = 200, .flip_edges = false});
  ASSERT_TRUE(with.isOk() && without.isOk());
  EXPECT_GT(with->edge_flips, 20u);
  EXPECT_EQ(without->edge_flips, 0u);
  EXPECT_EQ(with->positions, without->positions);
  const auto regularTriangles = [](const Remeshed& r) {
    std::multiset<std::array<Vec3d, 3>> out;
    for (size_t t = 0; t < r.triangles.size(); ++t)
      if (r.regular[t]) {
        std::array<Vec3d, 3> c;
        for (int k = 0; k < 3; ++k) c[size_t(k)] = r.positions[r.triangles[t][size_t(k)]];
        std::rotate(c.begin(), std::min_element(c.begin(), c.end()), c.end());
        out.insert(c);
      }
    return out;
  };
  EXPECT_TRUE(regularTriangles(*with) == regularTriangles(*without));
  const auto area = [](const Remeshed& r) {
    double a = 0;
    for (const Triangle& t : r.triangles)
      a += vlen(vcross(vsub(r.positions[t[1]], r.positions[t[0]]), vsub(r.positions[t[2]], r.positions[t[0]]))) / 2;
    return a;
  };
  EXPECT_LT(area(*with), area(*without));
  const EdgeCheck c = checkEdges(with->positions, with->triangles);
  EXPECT_EQ(c.boundary, 0u);
  EXPECT_EQ(c.non_manifold, 0u);
  EXPECT_EQ(int64_t(usedVertices(with->triangles)) - int64_t(c.edges) + int64_t(with->triangles.size()), 2);
  // The sphere's centre and radius on the grid: the mean and the mean distance of the input's vertices.
  Vec3d centre{0, 0, 0};
  for (const Vec3u& p : m.positions) centre = vadd(centre, Vec3d{double(p[0]), double(p[1]), double(p[2])});
  centre = vmul(centre, 1.0 / double(m.positions.size()));
  double radius = 0;
  for (const Vec3u& p : m.positions) radius += vlen(vsub(Vec3d{double(p[0]), double(p[1]), double(p[2])}, centre));
  radius /= double(m.positions.size());
  double worst = 0;
  for (const Triangle& t : with->triangles) {
    const Vec3d a = with->positions[t[0]], b = with->positions[t[1]], d = with->positions[t[2]];
    const Vec3d mid = vmul(vadd(vadd(a, b), d), 1.0 / 3);
    EXPECT_GT(vdot(vcross(vsub(b, a), vsub(d, a)), vsub(mid, centre)), 0);
    worst = std::max(worst, std::abs(vlen(vsub(mid, centre)) - radius));
  }
  // A triangle of the 200-cell lattice, slanted up to 1 / tau = 5 times, has chords of at most 1000 cells; its
  // centroid is within their sag, 1000^2 / (8 r), plus the input's own chords' sag and rounding.
  EXPECT_LT(worst, 1000.0 * 1000.0 / (8 * radius) + 20);
  std::printf("%llu flips, area %.9g -> %.9g, worst centroid %.3g cells off the sphere\n",
              static_cast<unsigned long long>(with->edge_flips), area(*without), area(*with), worst);
}

TEST(Remesh, TorusKeepsItsGenus) {
  const QuantizedMesh m = quantized(torus(120, 60, 1.0, 0.35), 14);
  auto r = remeshPiecewiseRegular(m, {}, {.tau = 0.2, .spacing = 160});
  ASSERT_TRUE(r.isOk()) << r.status().toString();
  const EdgeCheck c = checkEdges(r->positions, r->triangles);
  EXPECT_EQ(c.boundary, 0u);
  EXPECT_EQ(c.non_manifold, 0u);
  EXPECT_EQ(int64_t(usedVertices(r->triangles)) - int64_t(c.edges) + int64_t(r->triangles.size()), 0);
  EXPECT_GT(regularShare(*r), 0.5);
}

// A tile: a hemisphere whose rim is locked. Locked vertices keep their positions, rim edges stay edges, and the
// boundary is exactly the rim.
TEST(Remesh, LockedTileBorderIsKept) {
  const testing::LockedCap cap = testing::lockedCap(quantized(icosphere(4), 14), 14, 100);
  const QuantizedMesh& half = cap.mesh;
  const std::vector<uint8_t>& locked = cap.locked;
  const EdgeCheck in = checkEdges(doubles(half), half.triangles);
  auto r = remeshPiecewiseRegular(half, locked, {.tau = 0.2, .spacing = 300});
  ASSERT_TRUE(r.isOk()) << r.status().toString();
  const EdgeCheck c = checkEdges(r->positions, r->triangles);
  EXPECT_EQ(c.non_manifold, 0u);
  EXPECT_EQ(c.boundary, in.boundary);  // the same rim edges, no more
  EXPECT_NEAR(c.boundary_length, in.boundary_length, 1e-6 * in.boundary_length);
  std::map<uint32_t, uint32_t> merged_of_input;
  for (uint32_t v = 0; v < r->positions.size(); ++v)
    if (r->input_vertex[v] != UINT32_MAX) merged_of_input[r->input_vertex[v]] = v;
  std::set<std::pair<uint32_t, uint32_t>> edges;
  for (const Triangle& t : r->triangles)
    for (int k = 0; k < 3; ++k) edges.insert(std::minmax(t[size_t(k)], t[size_t((k + 1) % 3)]));
  for (const auto& e : cap.rim) {
    ASSERT_TRUE(merged_of_input.count(e.first) && merged_of_input.count(e.second));
    const uint32_t a = merged_of_input[e.first], b = merged_of_input[e.second];
    EXPECT_TRUE(edges.count(std::minmax(a, b))) << "rim edge " << e.first << "-" << e.second << " lost";
    EXPECT_EQ(r->positions[a], (Vec3d{double(half.positions[e.first][0]), double(half.positions[e.first][1]),
                                      double(half.positions[e.first][2])}));
  }
}

// Ugly inputs: a collinear triangle with corners near 2^24 (its orientation is rounding noise of lattice
// coordinates, not "facing away"), a triangle repeating a vertex inside a sphere (kept, no new non-manifold edge),
// corners beyond 2^25 (refused), and a grid so fine that four triangles would make millions of pieces (refused,
// kLimitExceeded, before any memory is spent).
TEST(Remesh, UglyInputsAndAGridTooFine) {
  QuantizedMesh line;
  line.positions = {{3841504, 4085772, 3755581}, {3852691, 4097616, 3760942}, {3848962, 4093668, 3759155}};
  line.triangles = {{0, 1, 2}};
  for (uint32_t spacing : {2u, 64u, 1000u}) {
    auto r = remeshPiecewiseRegular(line, {}, {.tau = 0.2, .spacing = spacing});
    EXPECT_TRUE(r.isOk()) << spacing << ": " << r.status().toString();
  }
  QuantizedMesh sphere = quantized(icosphere(3), 14);
  const Triangle t0 = sphere.triangles[0];
  sphere.triangles.push_back({t0[0], t0[0], t0[1]});
  const EdgeCheck in = checkEdges(doubles(sphere), sphere.triangles);
  auto r = remeshPiecewiseRegular(sphere, {}, {.tau = 0.2, .spacing = 1200});
  ASSERT_TRUE(r.isOk()) << r.status().toString();
  EXPECT_LE(checkEdges(r->positions, r->triangles).non_manifold, in.non_manifold);
  QuantizedMesh far = line;
  far.positions[1][0] = 1u << 26;
  EXPECT_EQ(remeshPiecewiseRegular(far, {}, {.tau = 0.2, .spacing = 64}).status().code(), ErrorCode::kInvalidArgument);
  QuantizedMesh tetra;
  tetra.positions = {{0, 0, 0}, {60000, 0, 0}, {0, 60000, 0}, {0, 0, 60000}};
  tetra.triangles = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}};
  auto fine = remeshPiecewiseRegular(tetra, {}, {.tau = 0.2, .spacing = 2});
  ASSERT_FALSE(fine.isOk());
  EXPECT_EQ(fine.status().code(), ErrorCode::kLimitExceeded);
  EXPECT_NE(fine.status().message().find("too fine"), std::string::npos) << fine.status().toString();
  EXPECT_TRUE(remeshPiecewiseRegular(tetra, {}, {.tau = 0.2, .spacing = 6000}).isOk());
}

TEST(Remesh, RefusesBadOptions) {
  const QuantizedMesh m = quantized(icosphere(1), 10);
  EXPECT_FALSE(remeshPiecewiseRegular(m, {}, {.tau = 0.2, .spacing = 7}).isOk());
  EXPECT_FALSE(remeshPiecewiseRegular(m, {}, {.tau = 0.2, .spacing = 0}).isOk());
  EXPECT_FALSE(remeshPiecewiseRegular(m, {}, {.tau = 0.7, .spacing = 8}).isOk());
  EXPECT_FALSE(remeshPiecewiseRegular(m, std::vector<uint8_t>(2), {.tau = 0.2, .spacing = 8}).isOk());
  auto empty = remeshPiecewiseRegular(QuantizedMesh{}, {}, {.tau = 0.2, .spacing = 8});
  ASSERT_TRUE(empty.isOk());
  EXPECT_TRUE(empty->triangles.empty());
}

// Real scans at 12 bits: the result is manifold where the input is (no edge gains uses), its boundary is the input's
// (same length), and no triangle is lost or doubled (the projected area of each relief's triangles... is checked in
// test_resample; here the total area stays within 2% of the input's, the resampling of a curved surface).
// A scan of ../shared/data on a 12-bit grid (empty, with a failure, when it cannot be read).
QuantizedMesh scanAt12Bits(const std::filesystem::path& file) {
  auto mesh = readMeshFile(file.string());
  EXPECT_TRUE(mesh.isOk()) << mesh.status().toString();
  return mesh.isOk() ? quantized(*mesh, 12) : QuantizedMesh{};
}

TEST(RemeshScans, RealScansStayManifoldWithTheirBoundary) {
  const std::filesystem::path data = testing::sharedDataDir();
  if (!std::filesystem::exists(data)) GTEST_SKIP() << "shared data not found: " << data;
  for (const char* name : {"bun_zipper.ply.zst", "horse.ply.zst"}) {
    SCOPED_TRACE(name);
    const QuantizedMesh q = scanAt12Bits(data / name);
    const EdgeCheck in = checkEdges(doubles(q), q.triangles);
    auto r = remeshPiecewiseRegular(q, {}, {.tau = 0.2, .spacing = 24});
    ASSERT_TRUE(r.isOk()) << r.status().toString();
    const EdgeCheck c = checkEdges(r->positions, r->triangles);
    EXPECT_LE(c.non_manifold, in.non_manifold);
    EXPECT_NEAR(c.boundary_length, in.boundary_length, 1e-6 * (1 + in.boundary_length));
    double area_in = 0, area_out = 0;
    const std::vector<Vec3d> p = doubles(q);
    for (const Triangle& t : q.triangles) area_in += triangleArea(p[t[0]], p[t[1]], p[t[2]]);
    for (const Triangle& t : r->triangles)
      area_out += triangleArea(r->positions[t[0]], r->positions[t[1]], r->positions[t[2]]);
    EXPECT_NEAR(area_out, area_in, 0.02 * area_in);
    std::printf("%s: %zu -> %zu triangles (%.1f%% regular), %u reliefs, %llu merge splits\n", name, q.triangles.size(),
                r->triangles.size(), 100 * regularShare(*r), r->reliefs,
                static_cast<unsigned long long>(r->merge_splits));
  }
}

// Rounding the remeshed vertices to the scan's integer grid (the remesh stage) moves an added point by up to 1.5
// cells, enough to flip the tiny triangles along relief boundaries. The stage places each point at the nearest free
// grid point that flips none of its triangles when one of its 27 candidates allows it: on bunny and horse, next
// to none of the remeshed triangles turn against their normal before rounding (1 each; 18 and 42 before).
TEST(RemeshScans, RoundingToTheGridFlipsAlmostNoTriangle) {
  const std::filesystem::path data = testing::sharedDataDir();
  if (!std::filesystem::exists(data)) GTEST_SKIP() << "shared data not found: " << data;
  for (const char* name : {"bun_zipper.ply.zst", "horse.ply.zst"}) {
    SCOPED_TRACE(name);
    const QuantizedMesh q = scanAt12Bits(data / name);
    auto r = remeshPiecewiseRegular(q, {}, {.tau = 0.2, .spacing = 20});
    ASSERT_TRUE(r.isOk()) << r.status().toString();
    auto staged = remeshTile(TileContext{12, {}}, TileView{q, {}}, 0.2, 20);
    ASSERT_TRUE(staged.isOk()) << staged.status().toString();
    ASSERT_EQ(staged->mesh.triangles.size(), r->triangles.size());  // nothing welded: the same triangles in order
    const std::vector<Vec3d> rounded = doubles(staged->mesh);
    size_t flipped = 0;
    for (size_t t = 0; t < r->triangles.size(); ++t) {
      const Triangle &a = r->triangles[t], &b = staged->mesh.triangles[t];
      const Vec3d before =
          vcross(vsub(r->positions[a[1]], r->positions[a[0]]), vsub(r->positions[a[2]], r->positions[a[0]]));
      const Vec3d after = vcross(vsub(rounded[b[1]], rounded[b[0]]), vsub(rounded[b[2]], rounded[b[0]]));
      flipped += vdot(before, before) > 0 && !(vdot(before, after) > 0);
    }
    std::printf("%s: %zu of %zu triangles turned against their normal by rounding\n", name, flipped,
                r->triangles.size());
    EXPECT_LE(flipped, 5u);
  }
}

// The direct fill of a relief's inside (ResampleMethod::kDirect, the default) against slicing and collapsing every
// triangle as the paper does (kSliceAll), a second implementation: on real scans the two give the same regular
// triangles, to within the few cells next to the irregular band where the order of collapses differs, with the
// same grid vertices (positions to rounding). (RealScansStayManifoldWithTheirBoundary checks the direct result, the
// default, for manifoldness and boundary.)
TEST(RemeshScans, DirectFillMatchesSlicingEveryTriangle) {
  const std::filesystem::path data = testing::sharedDataDir();
  if (!std::filesystem::exists(data)) GTEST_SKIP() << "shared data not found: " << data;
  for (const char* name : {"bun_zipper.ply.zst", "horse.ply.zst"}) {
    SCOPED_TRACE(name);
    const QuantizedMesh q = scanAt12Bits(data / name);
    auto direct = remeshPiecewiseRegular(q, {}, {.tau = 0.2, .spacing = 24});
    auto sliced = remeshPiecewiseRegular(q, {}, {.tau = 0.2, .spacing = 24, .resample = ResampleMethod::kSliceAll});
    ASSERT_TRUE(direct.isOk()) << direct.status().toString();
    ASSERT_TRUE(sliced.isOk()) << sliced.status().toString();
    // Regular triangles as their corners' positions, rounded to 1e-6 grid units.
    const auto regular = [](const Remeshed& r) {
      std::vector<std::array<int64_t, 9>> out;
      for (size_t t = 0; t < r.triangles.size(); ++t) {
        if (!r.regular[t]) continue;
        std::array<std::array<int64_t, 3>, 3> c{};
        for (size_t k = 0; k < 3; ++k)
          for (size_t d = 0; d < 3; ++d) c[k][d] = std::llround(r.positions[r.triangles[t][k]][d] * 1e6);
        std::sort(c.begin(), c.end());
        out.push_back({c[0][0], c[0][1], c[0][2], c[1][0], c[1][1], c[1][2], c[2][0], c[2][1], c[2][2]});
      }
      std::sort(out.begin(), out.end());
      return out;
    };
    const auto a = regular(*direct), b = regular(*sliced);
    std::vector<std::array<int64_t, 9>> common;
    std::set_intersection(a.begin(), a.end(), b.begin(), b.end(), std::back_inserter(common));
    std::printf("%s: direct %zu triangles, %zu regular; sliced %zu, %zu regular; %zu regular in common\n", name,
                direct->triangles.size(), a.size(), sliced->triangles.size(), b.size(), common.size());
    EXPECT_GE(double(common.size()), 0.995 * double(b.size()));
    EXPECT_GE(double(common.size()), 0.995 * double(a.size()));
    EXPECT_NEAR(double(direct->triangles.size()), double(sliced->triangles.size()),
                0.005 * double(sliced->triangles.size()));
  }
}

// The remesh stage through the tiled pipeline, then edgebreaker: igea in about 30 tiles at 12 bits. No tile fails
// (every tile's border contract holds), the decoded tiles weld crack-free (no position twice, igea stays closed),
// the measured symmetric RMS stays within a quarter of the grid spacing, and the container is smaller than the
// lossless one.
TEST(RemeshScans, TiledIgeaThroughTheRemeshStageWeldsCrackFree) {
  const std::string igea = testing::sharedDataDir() + "/igea.ply.zst";
  if (!std::filesystem::exists(igea)) GTEST_SKIP() << "shared data not found: " << igea;
  testing::TempDir dir;
  EncodeSettings s;
  s.input = igea;
  s.codec = "edgebreaker";
  s.bits = 12;
  s.tile_triangles = 8192;
  s.threads = 2;
  s.output = dir.file("lossless.spz");
  auto lossless = encodeFile(s);
  ASSERT_TRUE(lossless.isOk()) << lossless.status().toString();
  StageSpec remesh;
  remesh.kind = StageKind::kRemesh;
  remesh.remesh.grid = 0.005;  // 20 cells
  s.stages = {remesh};
  s.measure.enabled = true;
  s.output = dir.file("remeshed.spz");
  auto r = encodeFile(s);
  ASSERT_TRUE(r.isOk()) << r.status().toString();
  EXPECT_GE(r->tiles.size(), 20u);
  EXPECT_EQ(r->failed_tiles, 0u);
  auto m = decodeContainer(s.output, std::nullopt, nullptr);
  ASSERT_TRUE(m.isOk()) << m.status().toString();
  std::set<Vec3u> positions(m->positions.begin(), m->positions.end());
  EXPECT_EQ(positions.size(), m->positions.size()) << "duplicate positions on seams";
  const EdgeCheck c = checkEdges(doubles(*m), m->triangles);
  EXPECT_EQ(c.boundary, 0u) << "igea is closed: remeshed tiles opened seams";
  EXPECT_EQ(c.non_manifold, 0u) << "seams welded into non-manifold edges";
  const ErrorStats error = symmetricOf(statsOf(r->forward), statsOf(r->backward));
  const double cell = r->diagonal / (std::sqrt(3.0) * 4096);  // about: the diagonal spans up to sqrt(3) extents
  EXPECT_LT(error.rms, 0.25 * 20 * std::sqrt(3.0) * cell);
  EXPECT_LT(r->bytes, lossless->bytes);
  // The same bytes on one thread (tiles in another order).
  const std::string two_threads = s.output;
  s.threads = 1;
  s.measure.enabled = false;
  s.output = dir.file("one_thread.spz");
  ASSERT_TRUE(encodeFile(s).isOk());
  EXPECT_TRUE(testing::readBytes(s.output) == testing::readBytes(two_threads)) << "not byte-identical";
  std::printf("igea: %zu tiles, %llu -> %zu triangles, %llu -> %llu bytes, RMS %.2e of the diagonal\n",
              r->tiles.size(), static_cast<unsigned long long>(lossless->faces), m->triangles.size(),
              static_cast<unsigned long long>(lossless->bytes), static_cast<unsigned long long>(r->bytes),
              error.rms / r->diagonal);
}

// Smaller tiles at 14 bits on bun_zipper (open: its holes' boundary is kept): the points grid lines put on tile
// borders must all be collapsed away, or the two tiles' copies weld into non-manifold seams. The decoded boundary
// has the input's length (up to rounding) and no edge has more than two triangles.
TEST(RemeshScans, SmallTilesOfAnOpenScanWeldManifold) {
  const std::string bunny = testing::sharedDataDir() + "/bun_zipper.ply.zst";
  if (!std::filesystem::exists(bunny)) GTEST_SKIP() << "shared data not found: " << bunny;
  testing::TempDir dir;
  EncodeSettings s;
  s.input = bunny;
  s.bits = 14;
  s.tile_triangles = 4096;
  s.threads = 2;
  s.output = dir.file("lossless.spz");
  ASSERT_TRUE(encodeFile(s).isOk());
  auto lossless = decodeContainer(s.output, std::nullopt, nullptr);
  ASSERT_TRUE(lossless.isOk());
  StageSpec remesh;
  remesh.kind = StageKind::kRemesh;
  remesh.remesh.grid = 0.003;  // 50 cells
  s.stages = {remesh};
  s.output = dir.file("remeshed.spz");
  auto r = encodeFile(s);
  ASSERT_TRUE(r.isOk()) << r.status().toString();
  EXPECT_GE(r->tiles.size(), 15u);
  EXPECT_EQ(r->failed_tiles, 0u);
  auto m = decodeContainer(s.output, std::nullopt, nullptr);
  ASSERT_TRUE(m.isOk()) << m.status().toString();
  const EdgeCheck in = checkEdges(doubles(*lossless), lossless->triangles);
  const EdgeCheck c = checkEdges(doubles(*m), m->triangles);
  EXPECT_EQ(c.non_manifold, 0u);
  // The holes' edges keep their ends; points left on them move off the line by their rounding only (a crack would
  // add whole edges, tens of cells each).
  EXPECT_NEAR(c.boundary_length, in.boundary_length, 1e-4 * in.boundary_length);
  EXPECT_NE(m->triangles.size(), lossless->triangles.size());  // remeshed, not tiles kept as they were
}

// `--codec prm` (remeshing and the PRM coder in one) on the bundled bunny in many tiles: the decoded scan is the
// one the `remesh` stage plus `edgebreaker` decodes to (an independent coder of the same remeshed tiles), smaller,
// welded as that one is; and on one and two threads the same bytes.
TEST(PrmCodec, TiledBunnyDecodesToTheRemeshStagesScan) {
  const std::string bunny = std::string(SCANPRESS_REPO_DATA) + "/bun_zipper.ply.zst";
  testing::TempDir dir;
  EncodeSettings s;
  s.input = bunny;
  s.bits = 12;
  s.tile_triangles = 8192;
  s.threads = 2;
  s.keep_colors = false;
  // Geometry alone: with the bunny's two float channels, interpolated at every added vertex, some tiles code
  // smaller as they are (prm keeps the smaller coding; Prm.ScalarChannelsAreResampledAndDecodeExactly).
  s.keep_scalars = false;
  s.codec = "edgebreaker";
  StageSpec remesh;
  remesh.kind = StageKind::kRemesh;
  remesh.remesh.grid = 0.008;
  s.stages = {remesh};
  s.output = dir.file("stage.spz");
  auto staged = encodeFile(s);
  ASSERT_TRUE(staged.isOk()) << staged.status().toString();
  s.stages.clear();
  s.codec = "prm";
  s.codec_options.prm.grid = 0.008;
  s.output = dir.file("prm.spz");
  auto coded = encodeFile(s);
  ASSERT_TRUE(coded.isOk()) << coded.status().toString();
  EXPECT_GE(coded->tiles.size(), 6u);
  EXPECT_EQ(coded->failed_tiles, 0u);
  auto a = decodeContainer(dir.file("stage.spz"), std::nullopt, nullptr);
  auto b = decodeContainer(s.output, std::nullopt, nullptr);
  ASSERT_TRUE(a.isOk() && b.isOk());
  EXPECT_TRUE(testing::triangleMultiset(*a) == testing::triangleMultiset(*b));
  EXPECT_LT(coded->bytes, 0.85 * double(staged->bytes));
  std::set<Vec3u> positions(b->positions.begin(), b->positions.end());
  EXPECT_EQ(positions.size(), b->positions.size()) << "duplicate positions on seams";
  EXPECT_EQ(checkEdges(doubles(*b), b->triangles).non_manifold, 0u);
  s.threads = 1;
  s.output = dir.file("prm1.spz");
  ASSERT_TRUE(encodeFile(s).isOk());
  EXPECT_TRUE(testing::readBytes(s.output) == testing::readBytes(dir.file("prm.spz"))) << "not byte-identical";
  std::printf("bunny: %zu tiles, remesh stage + edgebreaker %llu bytes, prm %llu bytes\n", coded->tiles.size(),
              static_cast<unsigned long long>(staged->bytes), static_cast<unsigned long long>(coded->bytes));
}

// `--codec prm --max-error E`: each tile chooses its lattice spacing so that the measured error meets E.
TEST(PrmCodec, ErrorTargetIsMetByChoosingTheSpacing) {
  const std::string bunny = std::string(SCANPRESS_REPO_DATA) + "/bun_zipper.ply.zst";
  testing::TempDir dir;
  EncodeSettings s;
  s.input = bunny;
  s.codec = "prm";
  s.bits = 12;
  s.tile_triangles = 32768;
  s.keep_colors = false;
  s.keep_scalars = false;  // geometry: with the bunny's noisy channels prm keeps its tiles as they are
  s.output = dir.file("prm.spz");
  s.target.kind = TargetKind::kMaxError;
  s.target.max_error = 2e-4;
  s.target.fixed_bits = true;
  s.measure.enabled = true;
  auto r = encodeFile(s);
  ASSERT_TRUE(r.isOk()) << r.status().toString();
  const ErrorStats error = symmetricOf(statsOf(r->forward), statsOf(r->backward));
  EXPECT_LE(error.rms, 2e-4 * r->diagonal);
  size_t remeshed = 0;
  for (const auto& t : r->tiles) remeshed += t.knob_cells > 0;
  EXPECT_GT(remeshed, 0u) << "no tile was remeshed";
  // Smaller than the scan coded losslessly at those bits.
  EncodeSettings lossless = s;
  lossless.codec = "edgebreaker";
  lossless.target = EncodeTarget{};
  lossless.measure.enabled = false;
  lossless.output = dir.file("lossless.spz");
  auto l = encodeFile(lossless);
  ASSERT_TRUE(l.isOk());
  EXPECT_LT(r->bytes, l->bytes);
  std::printf("bunny at RMS <= 2e-4: prm %llu bytes (RMS %.2e), lossless %llu bytes\n",
              static_cast<unsigned long long>(r->bytes), error.rms / r->diagonal,
              static_cast<unsigned long long>(l->bytes));
}

}  // namespace
}  // namespace scanpress
