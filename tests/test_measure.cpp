// Surface distance measurement (jobs/measure.h): exactness against analytic cases, the same numbers at any thread
// count, the per-tile report and the CLI; pictures (jobs/render.h). The closest-point queries underneath are
// tested in test_surface_index.cpp.
#include <gtest/gtest.h>

#include <oneapi/tbb/task_arena.h>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <limits>
#include <map>
#include <random>
#include <tuple>
#include <utility>

#include "engine/geometry.h"
#include "engine/metro.h"
#include "engine/quantize.h"
#include "engine/shapes.h"
#include "jobs/commands.h"
#include "jobs/config.h"
#include "jobs/container_file.h"
#include "jobs/measure.h"
#include "jobs/render.h"
#include "jobs/mesh_io/mesh_reader.h"
#include "jobs/mesh_io/mesh_writer.h"
#include "spatial/surface_index.h"
#include "spatial_util.h"
#include "jobs_util.h"
#include "png_util.h"

namespace scanpress {
namespace {

using testing::device;
using testing::grid;

TEST(Measure, IdenticalMeshesGiveZero) {
  const Mesh m = icosphere(3);
  MeasureSettings s;
  s.samples_per_triangle = 10;
  auto r = measureMeshes(m, m, s, device());
  ASSERT_TRUE(r.isOk()) << r.status().toString();
  EXPECT_LT(r->symmetric.max, 1e-12 * r->diagonal);
  EXPECT_LT(r->symmetric.mean, 1e-13 * r->diagonal);
  EXPECT_GT(r->forward.samples, 10u * m.triangles.size() / 2);
}

TEST(Measure, ParallelPlanesGiveTheOffset) {
  const Mesh a = grid(20, 0.0), b = grid(7, 0.0125);
  MeasureSettings s;
  s.samples = 20000;
  auto r = measureMeshes(a, b, s, device());
  ASSERT_TRUE(r.isOk());
  for (const ErrorStats& e : {r->forward, r->backward, r->symmetric}) {
    EXPECT_NEAR(e.mean, 0.0125, 1e-12);
    EXPECT_NEAR(e.rms, 0.0125, 1e-12);
    EXPECT_NEAR(e.max, 0.0125, 1e-12);
  }
  EXPECT_NEAR(r->diagonal, std::sqrt(2.0), 1e-12);
}

TEST(Measure, SphereAgainstInscribedIcosahedron) {
  // A fine icosphere (radius 1, 81920 faces; its own distance to the true sphere is below 1.3e-4) against the
  // inscribed icosahedron: the largest gap is above the face centers, 1 - inradius.
  const Mesh sphere = icosphere(6), ico = icosphere(0);
  const double inradius = std::sqrt((5.0 + 2.0 * std::sqrt(5.0)) / 15.0);  // circumradius 1
  MeasureSettings s;
  s.samples = 400000;
  auto r = measureMeshes(sphere, ico, s, device());
  ASSERT_TRUE(r.isOk());
  EXPECT_NEAR(r->backward.max, 1 - inradius, 2e-3);  // samples on the icosahedron, near face centers
  EXPECT_NEAR(r->forward.max, 1 - inradius, 2e-3);   // samples on the sphere above face centers
  EXPECT_LT(r->forward.mean, 1 - inradius);
}

TEST(Measure, SameNumbersAtAnyThreadCount) {
  const Mesh sphere = icosphere(4), ico = icosphere(1);
  MeasureSettings s;
  s.samples = 50000;
  MeasureResult one, two;
  tbb::task_arena(1).execute([&] { one = *measureMeshes(sphere, ico, s, device()); });
  tbb::task_arena(2).execute([&] { two = *measureMeshes(sphere, ico, s, device()); });
  EXPECT_EQ(one.forward.mean, two.forward.mean);
  EXPECT_EQ(one.forward.rms, two.forward.rms);
  EXPECT_EQ(one.backward.max, two.backward.max);
  EXPECT_EQ(one.forward.samples, two.forward.samples);
}

TEST(Measure, EncodeReportsTheErrorPerTileAndOverall) {
  const std::string path = testing::sharedDataDir() + "/igea.ply.zst";
  if (!std::filesystem::exists(path)) GTEST_SKIP() << "shared data not found: " << path;
  testing::TempDir dir;
  EncodeSettings s;
  s.input = path;
  s.output = dir.file("m.spz");
  s.bits = 12;
  s.tile_triangles = 16384;
  s.measure.enabled = true;
  s.threads = 1;
  auto one = encodeFile(s);
  ASSERT_TRUE(one.isOk()) << one.status().toString();
  s.threads = 2;
  auto two = encodeFile(s);
  ASSERT_TRUE(two.isOk());
  EXPECT_EQ(one->forward.sum, two->forward.sum) << "same numbers at any thread count";
  EXPECT_EQ(one->backward.max, two->backward.max);
  ASSERT_TRUE(one->measured);
  EXPECT_GE(one->tiles.size(), 16u);
  // The whole-mesh measurement of the decoded file agrees (per tile can only be a little larger at borders).
  auto original = readMeshFile(path);
  ContainerHeader header;
  auto decoded_q = decodeContainer(s.output, std::nullopt, &header);
  ASSERT_TRUE(decoded_q.isOk());
  const Mesh decoded = dequantizeMesh(*decoded_q, header.grid, header.layout);
  auto whole = measureMeshes(*original, decoded, s.measure, device());
  ASSERT_TRUE(whole.isOk());
  const ErrorStats f = statsOf(one->forward);
  EXPECT_NEAR(f.mean, whole->forward.mean, 0.03 * whole->forward.mean);
  EXPECT_NEAR(f.rms, whole->forward.rms, 0.03 * whole->forward.rms);
  EXPECT_NEAR(f.max, whole->forward.max, 0.15 * whole->forward.max);
  // Quantization bound: at most half a cell per axis.
  EXPECT_LE(f.max, header.grid.cell * std::sqrt(3.0) / 2 * (1 + 1e-9));
  for (const auto& t : one->tiles) {
    EXPECT_GT(t.forward.samples, 0u);
    EXPECT_LE(t.forward.max, f.max);
  }
}

// Issue 18. What a lossy codec makes of a mesh: positions snapped to a grid of `steps` cells over the largest
// extent (Draco's -qp), so that many triangles get two or three coincident corners.
Mesh snapped(const Mesh& m, int steps) {
  Mesh out = m;
  const BoundingBox box = boundingBox(m);
  double extent = 0;
  for (int a = 0; a < 3; ++a) extent = std::max(extent, box.hi[a] - box.lo[a]);
  const double cell = extent / steps;
  for (auto& p : out.positions)
    for (int a = 0; a < 3; ++a) p[a] = box.lo[a] + cell * std::round((p[a] - box.lo[a]) / cell);
  return out;
}

size_t degenerateCount(const Mesh& m) {
  size_t n = 0;
  for (const auto& t : m.triangles) {
    const Vec3d &a = m.positions[t[0]], &b = m.positions[t[1]], &c = m.positions[t[2]];
    n += a == b || b == c || c == a;
  }
  return n;
}

// Independent reference: the distance from p to the nearest triangle, each taken as the union of its face (if
// its projection falls inside, by the 2x2 normal equations in long double) and its edge segments (a point if
// the edge has zero length). Triangles whose bounding sphere is farther than the nearest sphere's far side
// are skipped (they cannot be nearer).
long double triangleDistance(const Vec3d& pd, const Mesh& m, const Triangle& tri) {
  using L = long double;
  auto dot = [](const L* u, const L* v) { return u[0] * v[0] + u[1] * v[1] + u[2] * v[2]; };
  const L p[3] = {pd[0], pd[1], pd[2]};
  L c[3][3];
  for (int k = 0; k < 3; ++k)
    for (int a = 0; a < 3; ++a) c[k][a] = m.positions[tri[k]][a];
  L best = std::numeric_limits<L>::infinity();
  for (int e = 0; e < 3; ++e) {
    const L* s = c[e];
    const L* f = c[(e + 1) % 3];
    const L d[3] = {f[0] - s[0], f[1] - s[1], f[2] - s[2]}, sp[3] = {p[0] - s[0], p[1] - s[1], p[2] - s[2]};
    const L len2 = dot(d, d);
    const L t = len2 > 0 ? std::clamp(dot(sp, d) / len2, L(0), L(1)) : L(0);
    const L r[3] = {sp[0] - t * d[0], sp[1] - t * d[1], sp[2] - t * d[2]};
    best = std::min(best, std::sqrt(dot(r, r)));
  }
  const L u[3] = {c[1][0] - c[0][0], c[1][1] - c[0][1], c[1][2] - c[0][2]},
          v[3] = {c[2][0] - c[0][0], c[2][1] - c[0][1], c[2][2] - c[0][2]},
          w[3] = {p[0] - c[0][0], p[1] - c[0][1], p[2] - c[0][2]};
  const L uu = dot(u, u), uv = dot(u, v), vv = dot(v, v), uw = dot(u, w), vw = dot(v, w);
  const L det = uu * vv - uv * uv;
  if (!(det > 1e-12L * uu * vv)) return best;
  const L a = (vv * uw - uv * vw) / det, b = (uu * vw - uv * uw) / det;
  if (a < 0 || b < 0 || a + b > 1) return best;
  const L r[3] = {w[0] - a * u[0] - b * v[0], w[1] - a * u[1] - b * v[1], w[2] - a * u[2] - b * v[2]};
  return std::min(best, std::sqrt(dot(r, r)));
}

class BruteForce {
 public:
  explicit BruteForce(const Mesh& m) : m_(m) {
    for (const auto& t : m.triangles) {  // center (the corners' mean) and radius, per triangle
      const Vec3d c = vmul(vadd(m.positions[t[0]], vadd(m.positions[t[1]], m.positions[t[2]])), 1.0 / 3);
      double r = 0;
      for (uint32_t v : t) r = std::max(r, vlen(vsub(m.positions[v], c)));
      spheres_.push_back({c, r * (1 + 1e-9)});
    }
  }
  double distance(const Vec3d& p) const {
    double reach = 1e300;
    for (const auto& [c, r] : spheres_) reach = std::min(reach, vlen(vsub(p, c)) + r);
    long double best = std::numeric_limits<long double>::infinity();
    for (size_t t = 0; t < m_.triangles.size(); ++t)
      if (vlen(vsub(p, spheres_[t].first)) - spheres_[t].second <= reach * (1 + 1e-9))
        best = std::min(best, triangleDistance(p, m_, m_.triangles[t]));
    return double(best);
  }

 private:
  const Mesh& m_;
  std::vector<std::pair<Vec3d, double>> spheres_;
};

// measureMeshes' statistics for one direction recomputed by brute force over the same samples (area samples
// in the mean and RMS, vertex samples in the max).
ErrorStats bruteForceStats(const Mesh& from, const Mesh& to, const MeasureSettings& s, double density,
                           uint64_t stream) {
  SampleOptions opt;
  opt.density = density;
  opt.seed = s.seed;
  opt.stratified = s.stratified;
  opt.vertices = false;
  opt.stream = stream;
  std::vector<Vec3d> samples;
  sampleSurface(from.positions, from.triangles, opt, samples);
  const BruteForce exact(to);
  ErrorAccumulator acc;
  for (const Vec3d& p : samples) acc.add(exact.distance(p));
  samples.clear();
  sampleVertices(from.positions, from.triangles, samples);
  for (const Vec3d& p : samples) acc.addToMax(exact.distance(p));
  return statsOf(acc);
}

TEST(Measure, DegenerateTrianglesMatchBruteForceBothWays) {
  // An icosphere snapped to a coarse grid: a third of its triangles have coincident corners (some all three),
  // others are collinear. Both directions (the degenerate mesh as target, then as source) against brute
  // force, at a density where distancesTo uses closest() and at one where it uses closestMany().
  const Mesh sphere = icosphere(3), lossy = snapped(sphere, 12);
  ASSERT_GT(degenerateCount(lossy), lossy.triangles.size() / 10);
  for (double per_triangle : {2.0, 8.0}) {
    MeasureSettings s;
    s.samples_per_triangle = per_triangle;
    auto r = measureMeshes(sphere, lossy, s, device());
    ASSERT_TRUE(r.isOk());
    const double density = samplingDensity(s, sphere.triangles.size(), surfaceArea(sphere.positions, sphere.triangles));
    const ErrorStats f = bruteForceStats(sphere, lossy, s, density, 0),
                     b = bruteForceStats(lossy, sphere, s, density, 1);
    for (auto [got, ref, name] : {std::tuple{r->forward, f, "forward"}, std::tuple{r->backward, b, "backward"}}) {
      SCOPED_TRACE(std::string(name) + " at " + std::to_string(per_triangle) + " samples per triangle");
      ASSERT_TRUE(std::isfinite(got.mean) && std::isfinite(got.rms) && std::isfinite(got.max));
      EXPECT_EQ(got.samples, ref.samples);
      EXPECT_NEAR(got.mean, ref.mean, 1e-12);
      EXPECT_NEAR(got.rms, ref.rms, 1e-12);
      EXPECT_NEAR(got.max, ref.max, 1e-12);
    }
  }
}

TEST(Measure, DegenerateTrianglesOnTheSurfaceAddNothing) {
  // Coincident-corner and collinear triangles laid on a surface's own edges and vertices do not change it:
  // the distance between the two is zero both ways.
  const Mesh sphere = icosphere(3);
  Mesh with = sphere;
  for (size_t k = 0; k < sphere.triangles.size(); ++k) {
    const Triangle& t = sphere.triangles[k];
    const Triangle kinds[3] = {{t[0], t[0], t[1]}, {t[1], t[2], t[2]}, {t[2], t[2], t[2]}};
    with.triangles.push_back(kinds[k % 3]);
  }
  MeasureSettings s;
  for (double per_triangle : {2.0, 8.0}) {
    s.samples_per_triangle = per_triangle;
    for (bool swap : {false, true}) {
      auto r = swap ? measureMeshes(with, sphere, s, device()) : measureMeshes(sphere, with, s, device());
      ASSERT_TRUE(r.isOk());
      EXPECT_LT(r->symmetric.max, 1e-14) << per_triangle << " " << swap;  // NaN fails too
      EXPECT_LT(r->symmetric.rms, 1e-14) << per_triangle << " " << swap;
    }
  }
}

TEST(Measure, CliOnADegenerateTarget) {
  // The CLI on files: a sphere against itself plus coincident-corner triangles on its edges (the NaN case:
  // the JSON had "mean": null), both ways.
  testing::TempDir dir;
  const Mesh sphere = icosphere(3);
  Mesh with = sphere;
  for (size_t k = 0; k < sphere.triangles.size(); k += 2)
    with.triangles.push_back({sphere.triangles[k][0], sphere.triangles[k][0], sphere.triangles[k][1]});
  ASSERT_TRUE(writeMeshFile(dir.file("a.ply"), sphere).isOk());
  ASSERT_TRUE(writeMeshFile(dir.file("b.ply"), with).isOk());
  for (auto [from, to] : {std::pair{"a.ply", "b.ply"}, std::pair{"b.ply", "a.ply"}}) {
    std::string text;
    const std::string args = "measure '" + dir.file(from) + "' '" + dir.file(to) + "' --json";
    ASSERT_EQ(testing::runScanpress(args, &text), 0) << text;
    EXPECT_EQ(text.find("null"), std::string::npos) << text;
    EXPECT_EQ(text.find("nan"), std::string::npos) << text;
    const nlohmann::json j = nlohmann::json::parse(text);
    for (const char* way : {"forward", "backward"})
      for (const char* stat : {"mean", "rms", "max"}) EXPECT_LT(j[way][stat].get<double>(), 1e-14) << way << stat;
  }
}

// An independent estimate of the area-weighted mean and RMS distance from `from` to `to`: `n` points uniform
// over the surface (a triangle by area, then uniform barycentric coordinates), plain Monte-Carlo.
std::pair<double, double> areaAverage(const Mesh& from, const Mesh& to, size_t n, uint32_t seed) {
  std::vector<double> cdf;
  double area = 0;
  for (const auto& t : from.triangles)
    cdf.push_back(area += triangleArea(from.positions[t[0]], from.positions[t[1]], from.positions[t[2]]));
  auto index = SurfaceIndex::build(device(), to.positions, to.triangles);
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(0, 1);
  double sum = 0, sum2 = 0;
  for (size_t i = 0; i < n; ++i) {
    const size_t t = std::lower_bound(cdf.begin(), cdf.end(), u(rng) * area) - cdf.begin();
    const auto& tri = from.triangles[std::min(t, from.triangles.size() - 1)];
    const double r1 = std::sqrt(u(rng)), r2 = u(rng);
    const Vec3d &a = from.positions[tri[0]], &b = from.positions[tri[1]], &c = from.positions[tri[2]];
    const Vec3d p = vadd(vmul(a, 1 - r1), vadd(vmul(b, r1 * (1 - r2)), vmul(c, r1 * r2)));
    const double d = index->closest(p).distance;
    sum += d, sum2 += d * d;
  }
  return {sum / double(n), std::sqrt(sum2 / double(n))};
}

TEST(Measure, MeanAndRmsEstimateTheAreaAverageAtTheDefaultDensity) {
  // A sphere whose vertices are pushed in or out by 1% at random: the error is largest at the vertices. At
  // the default density, mean and RMS both ways must agree within 3% with an independent area-sampled
  // estimate (400,000 points: its own noise is about 0.1%); vertex samples would bias them up.
  const Mesh sphere = icosphere(4);
  Mesh noisy = sphere;
  std::mt19937 rng(5);
  for (auto& p : noisy.positions) p = vmul(p, rng() % 2 ? 1.01 : 0.99);
  MeasureSettings s;
  auto r = measureMeshes(sphere, noisy, s, device());
  ASSERT_TRUE(r.isOk());
  const auto [fmean, frms] = areaAverage(sphere, noisy, 400000, 1);
  const auto [bmean, brms] = areaAverage(noisy, sphere, 400000, 2);
  EXPECT_NEAR(r->forward.mean, fmean, 0.03 * fmean);
  EXPECT_NEAR(r->forward.rms, frms, 0.03 * frms);
  EXPECT_NEAR(r->backward.mean, bmean, 0.03 * bmean);
  EXPECT_NEAR(r->backward.rms, brms, 0.03 * brms);
  EXPECT_NEAR(r->backward.max, 0.01, 1e-3) << "the vertices still count for the max";
}

TEST(Measure, IgeaAgainstItsEightBitSnapAtTheDefaultDensity) {
  // igea snapped to 255 steps over its largest extent (what Draco -qp 8 makes of positions; the issue's case
  // used a real Draco decode, which adds reordering): many triangles with coincident corners. Finite numbers,
  // and mean and RMS within 3% of an independent area-sampled estimate both ways.
  const std::string path = testing::sharedDataDir() + "/igea.ply.zst";
  if (!std::filesystem::exists(path)) GTEST_SKIP() << "shared data not found: " << path;
  auto igea = readMeshFile(path);
  ASSERT_TRUE(igea.isOk());
  const Mesh lossy = snapped(*igea, 255);
  ASSERT_GT(degenerateCount(lossy), 1000u);
  auto r = measureMeshes(*igea, lossy, MeasureSettings(), device());
  ASSERT_TRUE(r.isOk());
  const auto [fmean, frms] = areaAverage(*igea, lossy, 400000, 3);
  const auto [bmean, brms] = areaAverage(lossy, *igea, 400000, 4);
  EXPECT_NEAR(r->forward.mean, fmean, 0.03 * fmean);
  EXPECT_NEAR(r->forward.rms, frms, 0.03 * frms);
  EXPECT_NEAR(r->backward.mean, bmean, 0.03 * bmean);
  EXPECT_NEAR(r->backward.rms, brms, 0.03 * brms);
  // Snapping moves a point by at most half a cell's diagonal.
  const BoundingBox box = boundingBox(*igea);
  double extent = 0;
  for (int a = 0; a < 3; ++a) extent = std::max(extent, box.hi[a] - box.lo[a]);
  EXPECT_LE(r->symmetric.max, extent / 255 * std::sqrt(3.0) / 2);
}

TEST(Measure, CliJson) {
  testing::TempDir dir;
  const std::string bunny = std::string(SCANPRESS_REPO_DATA) + "/bun_zipper.ply.zst";
  std::string text;
  ASSERT_EQ(testing::runScanpress("measure '" + bunny + "' '" + bunny + "' --json --samples 20000", &text), 0) << text;
  for (const char* key : {"\"diagonal\"", "\"samples\"", "\"forward\"", "\"backward\"", "\"symmetric\"", "\"mean\"",
                          "\"rms\"", "\"max\"", "\"max_relative\""})
    EXPECT_NE(text.find(key), std::string::npos) << key;
}

}  // namespace
}  // namespace scanpress

namespace scanpress {
namespace {

using testing::decodePng;

TEST(Render, ShadedAndErrorColoredPicturesAreDeterministic) {
  const Mesh sphere = icosphere(4), ico = icosphere(1);
  RenderSettings s;
  s.width = 160;
  s.height = 120;
  RenderResult one, two;
  tbb::task_arena(1).execute([&] { one = *renderMesh(ico, s, device(), &sphere); });
  tbb::task_arena(2).execute([&] { two = *renderMesh(ico, s, device(), &sphere); });
  EXPECT_EQ(one.image.rgb, two.image.rgb);
  EXPECT_GT(one.scale_max, 0);
  EXPECT_LE(one.scale_max, 1 - std::sqrt((5.0 + 2.0 * std::sqrt(5.0)) / 15.0) + 1e-3);
  auto png = encodePng(one.image);
  ASSERT_TRUE(png.isOk());
  const Image back = decodePng(*png);
  ASSERT_EQ(back.width, 160);
  ASSERT_EQ(back.height, 120);
  EXPECT_EQ(back.rgb, one.image.rgb);
  // Colored (not grey) pixels where the mesh is, background elsewhere.
  size_t colored = 0, background = 0;
  for (size_t i = 0; i < back.rgb.size(); i += 3) {
    const uint8_t r = back.rgb[i], g = back.rgb[i + 1], b = back.rgb[i + 2];
    if (r == 245 && g == 245 && b == 245) ++background;
    else if (std::max({r, g, b}) - std::min({r, g, b}) > 40) ++colored;
  }
  EXPECT_GT(colored, 1000u);
  EXPECT_GT(background, 1000u);
  // Without a reference: grey shading only.
  auto grey = renderMesh(ico, s, device());
  ASSERT_TRUE(grey.isOk());
  for (size_t i = 0; i < grey->image.rgb.size(); i += 3) ASSERT_EQ(grey->image.rgb[i], grey->image.rgb[i + 2]);
  EXPECT_FALSE(renderMesh(Mesh(), s, device()).isOk());
}

// `--shade normals`: a cube whose faces have their own vertices and normals (its edges creases) shades as its flat
// faces do (within rounding); the same cube with one normal per corner position (the three faces' mean) does not,
// and neither does a sphere with its smooth normals against its facets.
TEST(Render, VertexNormalShadingShowsCreases) {
  Mesh cube;
  for (int axis = 0; axis < 3; ++axis)
    for (int side = 0; side < 2; ++side) {
      const uint32_t b = uint32_t(cube.positions.size());
      const int u = (axis + 1) % 3, v = (axis + 2) % 3;
      for (int i = 0; i < 4; ++i) {
        Vec3d p{0, 0, 0};
        p[size_t(axis)] = side ? 1 : -1;
        p[size_t(u)] = (i == 1 || i == 2) ? 1 : -1;
        p[size_t(v)] = (i >= 2) ? 1 : -1;
        cube.positions.push_back(p);
        Vec3f n{0, 0, 0};
        n[size_t(axis)] = side ? 1.f : -1.f;
        cube.normals.push_back(n);
      }
      cube.triangles.push_back({b, b + 1, b + 2});
      cube.triangles.push_back({b, b + 2, b + 3});
    }
  RenderSettings s;
  s.width = 160, s.height = 120;
  auto flat = renderMesh(cube, s, device());
  s.vertex_normals = true;
  auto own = renderMesh(cube, s, device());
  ASSERT_TRUE(flat.isOk() && own.isOk());
  size_t lit = 0, off = 0;
  for (size_t i = 0; i < flat->image.rgb.size(); ++i) {
    lit += flat->image.rgb[i] != 245;
    off += std::abs(int(flat->image.rgb[i]) - int(own->image.rgb[i])) > 1;
  }
  EXPECT_GT(lit, 3000u);
  EXPECT_EQ(off, 0u) << "the faces' own normals shade as the faces do";
  Mesh averaged = cube;
  for (size_t v = 0; v < averaged.positions.size(); ++v) {
    const Vec3d& p = averaged.positions[v];
    const double l = std::sqrt(3.0);
    averaged.normals[v] = {float(p[0] / l), float(p[1] / l), float(p[2] / l)};
  }
  auto merged = renderMesh(averaged, s, device());
  ASSERT_TRUE(merged.isOk());
  size_t differ = 0;
  for (size_t i = 0; i < flat->image.rgb.size(); ++i)
    differ += std::abs(int(flat->image.rgb[i]) - int(merged->image.rgb[i])) > 8;
  EXPECT_GT(differ, 1000u) << "one normal per corner position shades across the edges";
  // Without normals the option changes nothing.
  Mesh bare = cube;
  bare.normals.clear();
  auto plain = renderMesh(bare, s, device());
  ASSERT_TRUE(plain.isOk());
  EXPECT_EQ(plain->image.rgb, flat->image.rgb);
}

// The bounding box of the pixels that are not background, as {x0, y0, x1, y1} (inclusive); x0 > x1 when none.
std::array<int, 4> foreground(const Image& img, int x_end) {
  std::array<int, 4> b{img.width, img.height, -1, -1};
  for (int y = 0; y < img.height; ++y)
    for (int x = 0; x < x_end; ++x) {
      const uint8_t* p = &img.rgb[3 * (size_t(y) * img.width + x)];
      if (p[0] == 245 && p[1] == 245 && p[2] == 245) continue;
      b = {std::min(b[0], x), std::min(b[1], y), std::max(b[2], x), std::max(b[3], y)};
    }
  return b;
}

// A square [-h, h]^2 at height z (facing +z).
Mesh square(double h, double z) {
  Mesh m;
  m.positions = {{-h, -h, z}, {h, -h, z}, {h, h, z}, {-h, h, z}};
  m.triangles = {{0, 1, 2}, {0, 2, 3}};
  return m;
}

TEST(Render, TheCameraFramesTheModel) {
  // A sphere fills 90% of the smaller side; its box diagonal (what the camera used to fit) is sqrt(3) times wider.
  RenderSettings s;
  s.width = 160;
  s.height = 120;
  for (double az : {0.0, 30.0, 135.0}) {
    s.azimuth = az;
    auto r = renderMesh(icosphere(3), s, device());
    ASSERT_TRUE(r.isOk());
    const auto b = foreground(r->image, s.width);
    const double fx = double(b[2] - b[0] + 1) / s.width, fy = double(b[3] - b[1] + 1) / s.height;
    EXPECT_GE(std::max(fx, fy), 0.8) << az;
    EXPECT_LE(std::max(fx, fy), 0.95) << az;
    EXPECT_GT(b[0], 0);  // not cut
    EXPECT_GT(b[1], 0);
    EXPECT_LT(b[2], s.width - 1);
    EXPECT_LT(b[3], s.height - 1);
    EXPECT_LE(std::abs((b[0] + b[2]) - (s.width - 1)), 4) << az;  // centered
  }
  // A long thin strip seen from the front fills the width (its bounding sphere would fill the height).
  Mesh strip = square(1, 0);
  for (auto& p : strip.positions) p[0] *= 8, p[1] *= 0.5;
  s.azimuth = s.elevation = 0;
  auto r = renderMesh(strip, s, device());
  ASSERT_TRUE(r.isOk());
  const auto b = foreground(r->image, s.width);
  EXPECT_GE(double(b[2] - b[0] + 1) / s.width, 0.85);
}

TEST(Render, AFixedScaleGivesTheSameColorForTheSameDistance) {
  // Squares at distance 0.01 and 0.02 above a larger one; seen head-on, shading is 1 at the center, so a pixel
  // is the color ramp at distance / scale_max. With the bar fixed at 0.04 both pictures share one scale;
  // per-picture scales would paint both at the top of the ramp.
  const Mesh base = square(2, 0);
  RenderSettings s;
  s.width = 200;
  s.height = 160;
  s.azimuth = s.elevation = 0;
  const double diagonal = std::sqrt(32.0);
  s.scale_max_relative = 0.04 / diagonal;
  const int view_w = 200 - 60;
  struct Case {
    double z;
    std::array<int, 3> rgb;  // the ramp at z / 0.04, worked out by hand from its control points
  };
  for (const Case& c : {Case{0.01, {29, 191, 212}}, Case{0.02, {159, 242, 75}}}) {
    auto r = renderMesh(square(1, c.z), s, device(), &base);
    ASSERT_TRUE(r.isOk());
    EXPECT_NEAR(r->scale_max, 0.04, 1e-12);
    const uint8_t* p = &r->image.rgb[3 * (size_t(80) * 200 + view_w / 2)];
    for (int k = 0; k < 3; ++k) EXPECT_NEAR(p[k], c.rgb[k], 3) << c.z << " channel " << k;
  }
}

TEST(Render, ScaleLabelsInAbsoluteUnitsToo) {
  // The same scene ten times larger: the same picture in units of the diagonal, but the absolute label differs.
  const Mesh sphere = icosphere(4), ico = icosphere(1);
  Mesh big_sphere = sphere, big_ico = ico;
  for (auto& p : big_sphere.positions) p = vmul(p, 10.0);
  for (auto& p : big_ico.positions) p = vmul(p, 10.0);
  RenderSettings s;
  s.width = 200;
  s.height = 150;
  s.scale_max_relative = 0.01;
  auto a = renderMesh(ico, s, device(), &sphere), b = renderMesh(big_ico, s, device(), &big_sphere);
  ASSERT_TRUE(a.isOk() && b.isOk());
  EXPECT_NEAR(b->scale_max, 10 * a->scale_max, 1e-9);
  const int view_w = 200 - 60;
  size_t label_diff = 0;
  for (int y = 0; y < 30; ++y)  // the two label lines above the bar
    for (int x = view_w; x < 200; ++x)
      label_diff += a->image.rgb[3 * (size_t(y) * 200 + x)] != b->image.rgb[3 * (size_t(y) * 200 + x)];
  EXPECT_GT(label_diff, 5u);
}

TEST(Render, VertexColorsShadeTheSurface) {
  Mesh ico = icosphere(2);
  ico.colors.assign(ico.positions.size(), Rgba8{230, 30, 30, 255});
  for (size_t v = 0; v < ico.positions.size(); ++v)
    if (ico.positions[v][1] > 0) ico.colors[v] = {30, 30, 230, 255};
  ico.color_channels = 3;
  RenderSettings s;
  s.width = 160;
  s.height = 120;
  auto r = renderMesh(ico, s, device());
  ASSERT_TRUE(r.isOk());
  size_t red = 0, blue = 0;
  for (size_t i = 0; i < r->image.rgb.size(); i += 3) {
    const int R = r->image.rgb[i], G = r->image.rgb[i + 1], B = r->image.rgb[i + 2];
    red += R > G + 60 && R > B + 60;
    blue += B > G + 60 && B > R + 60;
  }
  EXPECT_GT(red, 1000u);
  EXPECT_GT(blue, 1000u);
  // Through a PLY file (the reader keeps the colors).
  testing::TempDir dir;
  ASSERT_TRUE(writePly(dir.file("c.ply"), ico).isOk());
  std::string out;
  ASSERT_EQ(testing::runScanpress("render '" + dir.file("c.ply") + "' '" + dir.file("c.png") + "' --size 160,120",
                                  &out),
            0)
      << out;
  const Image img = decodePng(testing::readBytes(dir.file("c.png")));
  ASSERT_EQ(img.width, 160);
  size_t colored = 0;
  for (size_t i = 0; i < img.rgb.size(); i += 3) colored += img.rgb[i] > img.rgb[i + 1] + 60;
  EXPECT_GT(colored, 1000u);
  // With --against the distance colors win.
  auto against = renderMesh(ico, s, device(), &ico);
  ASSERT_TRUE(against.isOk());
  size_t red_against = 0;
  for (size_t i = 0; i < against->image.rgb.size(); i += 3)
    red_against += against->image.rgb[i] > 200 && against->image.rgb[i + 1] < 60 && against->image.rgb[i + 2] < 60;
  EXPECT_LT(red_against, 50u);
}

// Text pixels (the font's ink, 20,20,20) in rows [y0, y1).
size_t inkRows(const Image& img, int y0, int y1) {
  size_t n = 0;
  for (int y = y0; y < y1; ++y)
    for (int x = 0; x < img.width; ++x) {
      const uint8_t* p = &img.rgb[3 * (size_t(y) * img.width + x)];
      n += p[0] == 20 && p[1] == 20 && p[2] == 20;
    }
  return n;
}

TEST(Render, TheTitleIsDrawnOnTop) {
  RenderSettings s;
  s.width = 160;
  s.height = 120;
  auto plain = renderMesh(icosphere(1), s, device());
  s.title = "bun_zipper.ply";
  auto titled = renderMesh(icosphere(1), s, device());
  ASSERT_TRUE(plain.isOk() && titled.isOk());
  EXPECT_EQ(inkRows(plain->image, 0, 11), 0u);
  EXPECT_GT(inkRows(titled->image, 0, 11), 100u);  // 14 glyphs of about 15 pixels each
  EXPECT_EQ(inkRows(titled->image, 11, 120), 0u);  // the model below the band, not overdrawn
  // The CLI draws the mesh's file name.
  testing::TempDir dir;
  ASSERT_TRUE(writePly(dir.file("named.ply"), icosphere(1)).isOk());
  ASSERT_EQ(testing::runScanpress("render '" + dir.file("named.ply") + "' '" + dir.file("n.png") + "' --size 160,120"),
            0);
  EXPECT_GT(inkRows(decodePng(testing::readBytes(dir.file("n.png"))), 0, 11), 50u);
}

// prm's pictures (issue 21, part 7): a remeshed sphere's faces colored by relief. Independent truth: a face
// regular in relief r is a unit triangle of r's lattice, so its outward normal faces r's axis (+x, -x, +y, ...);
// the picture's counts are the container's; a legend swatch is drawn in its color; other codecs are refused.
TEST(Render, PrmContainersAreColoredByReliefAndRegularity) {
  testing::TempDir dir;
  ASSERT_TRUE(writePly(dir.file("s.ply"), icosphere(5)).isOk());
  std::string out;
  ASSERT_EQ(testing::runScanpress("encode '" + dir.file("s.ply") + "' '" + dir.file("s.spz") +
                                      "' --codec prm --bits 12 --grid 0.03 --quiet",
                                  &out),
            0)
      << out;
  auto picture = latticePicture(dir.file("s.spz"), LatticeColoring::kReliefs);
  ASSERT_TRUE(picture.isOk()) << picture.status().toString();
  auto file = ContainerFile::open(dir.file("s.spz"));
  ASSERT_TRUE(file.isOk());
  EXPECT_EQ(picture->faces, file->header().faces);
  EXPECT_EQ(picture->mesh.triangles.size(), picture->faces);
  ASSERT_EQ(picture->face_colors.size(), picture->faces);
  EXPECT_GT(double(picture->regular_faces), 0.6 * double(picture->faces));
  ASSERT_EQ(picture->legend.size(), 7u);  // six reliefs and "irregular"
  uint64_t regular = 0, facing = 0;
  for (size_t f = 0; f < picture->faces; ++f) {
    const Triangle& t = picture->mesh.triangles[f];
    const auto& c = picture->face_colors[f];
    const auto same = [&](const LegendEntry& e) { return e.rgb[0] == c[0] && e.rgb[1] == c[1] && e.rgb[2] == c[2]; };
    const auto it = std::find_if(picture->legend.begin(), picture->legend.end(), same);
    ASSERT_NE(it, picture->legend.end());
    const int relief = int(it - picture->legend.begin());
    if (relief == 6) continue;
    ++regular;
    const auto& p = picture->mesh.positions;
    const Vec3d n = vcross(vsub(p[t[1]], p[t[0]]), vsub(p[t[2]], p[t[0]]));
    facing += (relief % 2 == 0 ? 1 : -1) * n[size_t(relief / 2)] > 0;
  }
  EXPECT_EQ(regular, picture->regular_faces);
  EXPECT_EQ(facing, regular);
  auto by_regularity = latticePicture(dir.file("s.spz"), LatticeColoring::kRegularity);
  ASSERT_TRUE(by_regularity.isOk());
  EXPECT_EQ(by_regularity->legend.size(), 2u);
  EXPECT_EQ(by_regularity->regular_faces, picture->regular_faces);
  // Drawn whole, within a memory budget.
  auto tight = latticePicture(dir.file("s.spz"), LatticeColoring::kReliefs, 4096);
  ASSERT_FALSE(tight.isOk());
  EXPECT_EQ(tight.status().code(), ErrorCode::kLimitExceeded);
  EXPECT_NE(tight.status().message().find("memory budget"), std::string::npos) << tight.status().message();
  // The legend's first swatch, bottom left, in its color; a legend wider than the picture wraps (every swatch is
  // drawn), and the model stays above it.
  RenderSettings s;
  s.width = 160;
  s.height = 120;
  s.legend = {{"+x", {255, 0, 0}}};
  auto r = renderMesh(icosphere(1), s, device());
  ASSERT_TRUE(r.isOk());
  const uint8_t* swatch = &r->image.rgb[3 * (size_t(111) * 160 + 4)];
  EXPECT_TRUE(swatch[0] == 255 && swatch[1] == 0 && swatch[2] == 0);
  s.legend.clear();
  for (uint8_t k = 1; k <= 7; ++k) s.legend.push_back({"irregular", {uint8_t(30 * k), 0, uint8_t(255 - 30 * k)}});
  r = renderMesh(icosphere(1), s, device());
  ASSERT_TRUE(r.isOk());
  int lowest_model_row = -1;
  for (const LegendEntry& e : s.legend) {
    size_t n = 0;
    for (size_t i = 0; i < r->image.rgb.size(); i += 3)
      n += r->image.rgb[i] == e.rgb[0] && r->image.rgb[i + 1] == 0 && r->image.rgb[i + 2] == e.rgb[2];
    EXPECT_EQ(n, 49u) << int(e.rgb[0]);  // a 7x7 swatch at scale 1
  }
  for (int y = 0; y < 120; ++y)
    for (int x = 0; x < 160; ++x) {
      const uint8_t* p = &r->image.rgb[3 * (size_t(y) * 160 + x)];
      if (p[0] == p[1] && p[1] == p[2] && p[0] != 245 && p[0] > 40) lowest_model_row = y;  // shaded grey
    }
  EXPECT_LT(lowest_model_row, 120 - 12 * 4) << "seven entries of this width take four rows";
  // Face colors: one per triangle, for a mesh drawn whole without a reference.
  s.legend.clear();
  s.face_colors.assign(3, {255, 0, 0});
  EXPECT_EQ(renderMesh(icosphere(1), s, device()).status().code(), ErrorCode::kInvalidArgument);
  s.face_colors.assign(icosphere(1).triangles.size(), {255, 0, 0});
  r = renderMesh(icosphere(1), s, device());
  ASSERT_TRUE(r.isOk());
  size_t red = 0;
  for (size_t i = 0; i < r->image.rgb.size(); i += 3) red += r->image.rgb[i] > 60 && r->image.rgb[i + 1] == 0;
  EXPECT_GT(red, 1000u);
  // The CLI, and its refusals.
  const std::string render = "render '" + dir.file("s.spz") + "' '" + dir.file("r.png") + "' --size 160,120 ";
  EXPECT_EQ(testing::runScanpress(render + "--color-by reliefs", &out), 0) << out;
  EXPECT_NE(out.find(std::to_string(picture->faces) + " faces, " + std::to_string(picture->regular_faces) + " regular"),
            std::string::npos)
      << out;
  EXPECT_EQ(decodePng(testing::readBytes(dir.file("r.png"))).width, 160);
  EXPECT_EQ(testing::runScanpress(render + "--color-by regularity", &out), 0) << out;
  EXPECT_EQ(testing::runScanpress(render + "--color-by nope", &out), 1);
  EXPECT_NE(out.find("--color-by is"), std::string::npos) << out;
  EXPECT_EQ(testing::runScanpress(render + "--color-by reliefs --against '" + dir.file("s.ply") + "'", &out), 1);
  EXPECT_EQ(testing::runScanpress("render '" + dir.file("s.ply") + "' '" + dir.file("p.png") + "' --color-by reliefs",
                                  &out),
            1);
  EXPECT_NE(out.find("needs a prm container"), std::string::npos) << out;
  ASSERT_EQ(testing::runScanpress("encode '" + dir.file("s.ply") + "' '" + dir.file("k.spz") +
                                      "' --codec kdtree --bits 12 --quiet",
                                  &out),
            0);
  EXPECT_NE(testing::runScanpress("render '" + dir.file("k.spz") + "' '" + dir.file("k.png") + "' --color-by reliefs",
                                  &out),
            0);
  EXPECT_NE(out.find("coded with kdtree"), std::string::npos) << out;
  EXPECT_NE(out.find("k.spz"), std::string::npos) << out;
  EXPECT_FALSE(std::filesystem::exists(dir.file("k.png")));
}

TEST(Render, ScaleMaxOptionAndKeyAreValidated) {
  testing::TempDir dir;
  ASSERT_TRUE(writePly(dir.file("a.ply"), icosphere(1)).isOk());
  const std::string base = "render '" + dir.file("a.ply") + "' '" + dir.file("o.png") + "' ";
  for (const char* bad : {"-1", "0", "nan", "inf", "x", "1e400"}) {
    std::string out;
    EXPECT_NE(testing::runScanpress(base + "--against '" + dir.file("a.ply") + "' --scale-max " + bad, &out), 0) << bad;
    EXPECT_NE(out.find("--scale-max"), std::string::npos) << bad << ": " << out;
  }
  std::string out;
  EXPECT_NE(testing::runScanpress(base + "--scale-max 0.01", &out), 0);
  EXPECT_NE(out.find("--scale-max"), std::string::npos) << out;
  EXPECT_EQ(testing::runScanpress(base + "--against '" + dir.file("a.ply") + "' --scale-max 0.01", &out), 0) << out;

  // (1e400 fails in the JSON parser itself, which names the number rather than the key.)
  for (const char* bad : {"-1", "\"x\"", "2e6"}) {
    auto job =
        parseJobConfig(std::string(R"({"inputs": ["a.ply"], "measure": {"enabled": true, "scale_max": )") + bad + "}}",
                       "/x/j.json");
    ASSERT_FALSE(job.isOk()) << bad;
    EXPECT_NE(job.status().message().find("/measure/scale_max"), std::string::npos) << job.status().message();
  }
  auto job = parseJobConfig(R"({"inputs": ["a.ply"], "measure": {"enabled": true, "scale_max": 0.002}})", "/x/j.json");
  ASSERT_TRUE(job.isOk()) << job.status().message();
  EXPECT_EQ(job->encode.measure.scale_max, 0.002);
  job = parseJobConfig(R"({"inputs": ["a.ply"], "measure": {"enabled": true, "scale_max": 0}})", "/x/j.json");
  ASSERT_TRUE(job.isOk()) << job.status().message();  // 0, the default: each picture's own scale
  EXPECT_EQ(job->encode.measure.scale_max, 0.0);
}

TEST(Render, JobWritesTheErrorPicture) {
  testing::TempDir dir;
  const std::string bunny = std::string(SCANPRESS_REPO_DATA) + "/bun_zipper.ply.zst";
  testing::writeBytes(dir.file("job.json"),
                      "{\"inputs\": [\"" + bunny +
                          "\"], \"output\": {\"directory\": \"out\"}, "
                          "\"codec\": {\"bits\": 9}, \"measure\": {\"enabled\": true, \"render\": "
                          "true, \"render_size\": [200, 150], \"scale_max\": 0.001}}");
  const std::string cmd = std::string("'") + SCANPRESS_BIN + "' run '" + dir.file("job.json") + "' --quiet";
  ASSERT_EQ(std::system(cmd.c_str()), 0);
  const Image img = decodePng(testing::readBytes(dir.file("out/bun_zipper.error.png")));
  EXPECT_EQ(img.width, 200);
  EXPECT_EQ(img.height, 150);
  EXPECT_GT(inkRows(img, 0, 11), 50u);  // the input's name
  const std::string report(reinterpret_cast<const char*>(testing::readBytes(dir.file("out/bun_zipper.report.json"))
                                                             .data()),
                           testing::readBytes(dir.file("out/bun_zipper.report.json")).size());
  EXPECT_NE(report.find("\"max_relative\""), std::string::npos);
}

}  // namespace
}  // namespace scanpress
