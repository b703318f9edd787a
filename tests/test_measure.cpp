// Surface distance measurement: exactness against analytic cases and an independent brute-force reference.
#include <gtest/gtest.h>

#include <oneapi/tbb/task_arena.h>

#include <png.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <map>
#include <random>

#include "engine/geometry.h"
#include "engine/metro.h"
#include "engine/shapes.h"
#include "jobs/commands.h"
#include "jobs/measure.h"
#include "jobs/render.h"
#include "jobs/mesh_io/mesh_reader.h"
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

Image decodePng(const std::vector<uint8_t>& bytes) {
  png_image img;
  std::memset(&img, 0, sizeof img);
  img.version = PNG_IMAGE_VERSION;
  Image out;
  if (!png_image_begin_read_from_memory(&img, bytes.data(), bytes.size())) return out;
  img.format = PNG_FORMAT_RGB;
  out.width = static_cast<int>(img.width);
  out.height = static_cast<int>(img.height);
  out.rgb.resize(PNG_IMAGE_SIZE(img));
  if (!png_image_finish_read(&img, nullptr, out.rgb.data(), 0, nullptr)) out = Image();
  return out;
}

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
  for (size_t i = 0; i < grey->image.rgb.size(); i += 3)
    ASSERT_EQ(grey->image.rgb[i], grey->image.rgb[i + 2]);
  EXPECT_FALSE(renderMesh(Mesh(), s, device()).isOk());
}

TEST(Render, JobWritesTheErrorPicture) {
  testing::TempDir dir;
  const std::string bunny = std::string(SCANPRESS_REPO_DATA) + "/bun_zipper.ply.zst";
  testing::writeBytes(dir.file("job.json"), "{\"inputs\": [\"" + bunny + "\"], \"output\": {\"directory\": \"out\"}, "
                                            "\"codec\": {\"bits\": 9}, \"measure\": {\"enabled\": true, \"render\": "
                                            "true, \"render_size\": [200, 150]}}");
  const std::string cmd = std::string("'") + SCANPRESS_BIN + "' run '" + dir.file("job.json") + "' --quiet";
  ASSERT_EQ(std::system(cmd.c_str()), 0);
  const Image img = decodePng(testing::readBytes(dir.file("out/bun_zipper.error.png")));
  EXPECT_EQ(img.width, 200);
  EXPECT_EQ(img.height, 150);
  const std::string report(reinterpret_cast<const char*>(testing::readBytes(dir.file("out/bun_zipper.report.json")).data()),
                           testing::readBytes(dir.file("out/bun_zipper.report.json")).size());
  EXPECT_NE(report.find("\"max_relative\""), std::string::npos);
}

}  // namespace
}  // namespace scanpress
