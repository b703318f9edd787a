// Surface distance measurement (jobs/measure.h): exactness against analytic cases, the same numbers at any thread
// count, the per-tile report and the CLI; pictures (jobs/render.h). The closest-point queries underneath are
// tested in test_surface_index.cpp.
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
#include "jobs_util.h"

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
