// Measure and render a chunk at a time (jobs/chunked_surface.h, measureChunked, renderSurface): against the
// whole-mesh computations they must equal (bit for bit for measure, up to edge pixels for pictures), against
// brute force for the nearest-point search across chunks, over every source (runs of an in-memory mesh, mesh
// files whose vertices spill to disk, OBJ files that interleave vertices and faces, containers), with the ugly
// inputs (degenerate and coincident-corner triangles, stray vertices, soups, far outliers), and through the CLI.
#include <gtest/gtest.h>

#include <oneapi/tbb/task_arena.h>

#include <nlohmann/json.hpp>

#include <cmath>
#include <fstream>
#include <random>
#include <string>
#include <unordered_set>

#include "engine/geometry.h"
#include "engine/metro.h"
#include "engine/quantize.h"
#include "engine/shapes.h"
#include "jobs/chunked_surface.h"
#include "jobs/measure.h"
#include "jobs/mesh_io/mesh_reader.h"
#include "jobs/mesh_io/mesh_writer.h"
#include "jobs/pipeline.h"
#include "jobs/render.h"
#include "jobs/synth.h"
#include "spatial/surface_index.h"
#include "jobs_util.h"
#include "png_util.h"
#include "spatial_util.h"
#include "test_util.h"

namespace scanpress {
namespace {

using testing::device;
using testing::readBytes;
using testing::runScanpress;
using testing::TempDir;
using testing::writeBytes;

// A sphere displaced by a smooth bump field: another surface near the unit sphere.
Mesh bumpy(int levels, double amplitude) {
  Mesh m = icosphere(levels);
  for (Vec3d& p : m.positions) {
    const double f = 1 + amplitude * std::sin(5 * p[0]) * std::cos(3 * p[1] + p[2]);
    p = vmul(p, f);
  }
  return m;
}

// The ugly inputs: a stray vertex far away, zero-area and coincident-corner triangles, a duplicated (soup)
// triangle and a lone far triangle (an outlier whose nearest point is in another chunk).
Mesh ugly(Mesh m) {
  const uint32_t n = static_cast<uint32_t>(m.positions.size());
  m.positions.push_back({50, 50, 50});  // used by nothing
  m.positions.push_back(m.positions[0]);
  m.positions.push_back(vmul(vadd(m.positions[1], m.positions[2]), 0.5));
  m.triangles.push_back({0, n + 1, 1});    // coincident corners (0 and n+1 are the same point)
  m.triangles.push_back({1, 2, n + 2});    // zero area (n+2 on the edge 1-2)
  m.triangles.push_back({3, 3, 4});        // a repeated index
  m.triangles.push_back(m.triangles[10]);  // soup: the same triangle twice
  m.positions.push_back({3, 0, 0});
  m.positions.push_back({3.1, 0, 0});
  m.positions.push_back({3, 0.1, 0});
  m.triangles.push_back({n + 3, n + 4, n + 5});  // far from everything else
  return m;
}

void expectSameStats(const ErrorStats& a, const ErrorStats& b) {
  EXPECT_EQ(a.samples, b.samples);
  EXPECT_EQ(a.mean, b.mean);  // bit for bit
  EXPECT_EQ(a.rms, b.rms);
  EXPECT_EQ(a.max, b.max);
}

void expectSameMeasure(const MeasureResult& a, const MeasureResult& b) {
  EXPECT_EQ(a.diagonal, b.diagonal);
  expectSameStats(a.forward, b.forward);
  expectSameStats(a.backward, b.backward);
  expectSameStats(a.symmetric, b.symmetric);
}

TEST(ChunkedSurface, SamplerInPiecesEqualsOneCall) {
  const Mesh m = ugly(bumpy(3, 0.05));
  for (bool stratified : {true, false}) {
    SampleOptions opt;
    opt.density = 3000;
    opt.stratified = stratified;
    opt.vertices = false;
    std::vector<Vec3d> whole, pieces;
    sampleSurface(m.positions, m.triangles, opt, whole);
    SurfaceSampler sampler(opt);
    const std::span<const Triangle> t(m.triangles);
    for (size_t first = 0; first < t.size(); first += 37)
      sampler.sample(m.positions, t.subspan(first, std::min<size_t>(37, t.size() - first)), pieces);
    ASSERT_GT(whole.size(), 1000u);
    EXPECT_EQ(whole, pieces);
  }
}

TEST(ChunkedSurface, ChunksCoverTheMeshInOrder) {
  const Mesh m = ugly(bumpy(3, 0.05));
  for (uint64_t run : {1, 7, 100, 100000}) {
    const ChunkedSurface c = ChunkedSurface::pieces(m, run);
    EXPECT_EQ(c.triangles(), m.triangles.size());
    EXPECT_EQ(c.area(), surfaceArea(m.positions, m.triangles));  // summed in the same order
    EXPECT_EQ(c.box().lo, boundingBox(m).lo);
    EXPECT_EQ(c.box().hi, boundingBox(m).hi);  // the stray vertex too
    EXPECT_EQ(c.usedBox().hi, usedBoundingBox(m).hi);
    size_t t = 0;
    for (size_t i = 0; i < c.chunks(); ++i) {
      auto chunk = c.load(i);
      ASSERT_TRUE(chunk.isOk());
      for (const Triangle& tri : (*chunk)->triangles) {
        ASSERT_LT(t, m.triangles.size());
        for (int k = 0; k < 3; ++k) ASSERT_EQ((*chunk)->positions[tri[k]], m.positions[m.triangles[t][k]]);
        ++t;
      }
    }
    EXPECT_EQ(t, m.triangles.size());
  }
}

TEST(ChunkedSurface, NearestOverChunksMatchesBruteForce) {
  const Mesh m = ugly(bumpy(2, 0.08));
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> u(-1.6, 1.6);
  std::vector<Vec3d> points;
  for (int i = 0; i < 400; ++i) points.push_back({u(rng), u(rng), u(rng)});
  points.push_back({40, -30, 20});   // far from everything: every chunk must be considered
  points.push_back(m.positions[5]);  // on the surface
  for (uint64_t run : {1, 13, 1000}) {
    const ChunkedSurface c = ChunkedSurface::pieces(m, run);
    for (uint64_t cache : {uint64_t(1), uint64_t(1) << 30}) {  // one index at a time, or all of them
      ChunkIndexCache indexes(c, device(), cache);
      std::vector<double> best;
      ASSERT_TRUE(nearestSquared(c, indexes, points, best).isOk());
      for (size_t k = 0; k < points.size(); ++k) {
        double brute = INFINITY;
        for (const Triangle& t : m.triangles) {
          const Vec3d q = closestPointOnTriangle(points[k], m.positions[t[0]], m.positions[t[1]], m.positions[t[2]]);
          brute = std::min(brute, vdot(vsub(q, points[k]), vsub(q, points[k])));
        }
        ASSERT_EQ(best[k], brute) << "point " << k << ", run " << run;
      }
    }
  }
}

TEST(ChunkedSurface, MeasureEqualsTheWholeMeshBitForBit) {
  const Mesh a = ugly(bumpy(4, 0.02)), b = ugly(bumpy(2, 0.03));
  for (bool vertices : {true, false}) {
    MeasureSettings s;
    s.samples_per_triangle = 3;
    s.vertices = vertices;
    auto whole = measureMeshes(a, b, s, device());
    ASSERT_TRUE(whole.isOk()) << whole.status().toString();
    // Runs of three triangles to a thousand; a cache of one index (rebuilt whenever another chunk is asked for) or
    // of all of them.
    for (const auto& run_cache :
         {std::pair<uint64_t, uint64_t>{3, uint64_t(1) << 30}, {29, 1}, {1000, 1}, {1000, 1u << 30}}) {
      // (A plain variable, not a structured binding: clang 14, the sanitizer lane's compiler, cannot capture those.)
      const uint64_t run = run_cache.first, cache = run_cache.second;
      const ChunkedSurface ca = ChunkedSurface::pieces(a, run), cb = ChunkedSurface::pieces(b, run + 3);
      MeasureResult chunked;
      tbb::task_arena(2).execute([&] { chunked = *measureChunked(ca, cb, s, cache, device()); });
      expectSameMeasure(chunked, *whole);
    }
    // Monte-Carlo sampling and a sample count instead of a density.
    s.stratified = false;
    s.samples = 20000;
    whole = measureMeshes(a, b, s, device());
    auto chunked = measureChunked(ChunkedSurface::pieces(a, 50), ChunkedSurface::pieces(b, 50), s, 1, device());
    ASSERT_TRUE(chunked.isOk());
    expectSameMeasure(*chunked, *whole);
  }
}

TEST(ChunkedSurface, PointCloudsAreRefusedAsInMemory) {
  Mesh cloud = icosphere(2);
  cloud.triangles.clear();
  const Mesh sphere = icosphere(2);
  auto r = measureChunked(ChunkedSurface::whole(cloud), ChunkedSurface::whole(sphere), {}, 1 << 20, device());
  ASSERT_FALSE(r.isOk());
  EXPECT_EQ(r.status().code(), ErrorCode::kUnsupported);
  RenderSettings rs;
  EXPECT_FALSE(renderSurface(ChunkedSurface::whole(cloud), rs, device(), nullptr, 1 << 20).isOk());
}

// An OBJ whose vertices come just before the first face that uses them (vertices and faces interleaved).
void writeInterleavedObj(const std::string& path, const Mesh& m) {
  std::ofstream out(path);
  std::vector<int64_t> index(m.positions.size(), -1);
  int64_t next = 0;
  char line[128];
  for (const Triangle& t : m.triangles) {
    for (uint32_t v : t)
      if (index[v] < 0) {
        index[v] = ++next;
        std::snprintf(line, sizeof line, "v %.17g %.17g %.17g\n", m.positions[v][0], m.positions[v][1],
                      m.positions[v][2]);
        out << line;
      }
    out << "f " << index[t[0]] << ' ' << index[t[1]] << ' ' << index[t[2]] << '\n';
  }
}

// A synth scan of `triangles` written to dir/name; its path.
std::string synthFile(const TempDir& dir, const std::string& name, uint64_t triangles, uint64_t seed = 1) {
  SynthSettings synth;
  synth.output = dir.file(name);
  synth.triangles = triangles;
  synth.seed = seed;
  EXPECT_TRUE(synthesize(synth).isOk());
  return synth.output;
}

TEST(ChunkedSurface, MeshFilesSpillTheirVerticesAndMeasureTheSame) {
  TempDir dir;
  // Over 65,536 vertices: the smallest vertex cache (4 blocks of 16,384) spills to its scratch file.
  synthFile(dir, "a.ply", 160000);
  synthFile(dir, "b.ply", 40000, 2);
  auto a = readMeshFile(dir.path() + "/a.ply");
  auto b = readMeshFile(dir.path() + "/b.ply");
  ASSERT_TRUE(a.isOk() && b.isOk());
  writeInterleavedObj(dir.path() + "/a.obj", *a);
  MeasureSettings s;
  s.samples_per_triangle = 0.25;
  auto whole = measureMeshes(*a, *b, s, device());
  ASSERT_TRUE(whole.isOk());
  for (const char* name : {"/a.ply", "/a.obj"}) {
    auto ca = ChunkedSurface::fromMeshFile(dir.path() + name, 5000, 1, dir.path());
    ASSERT_TRUE(ca.isOk()) << ca.status().toString();
    EXPECT_EQ(ca->triangles(), a->triangles.size());
    EXPECT_GE(ca->chunks(), 32u);
    auto cb = ChunkedSurface::fromMeshFile(dir.path() + "/b.ply", 3000, 1, dir.path());
    ASSERT_TRUE(cb.isOk());
    auto chunked = measureChunked(*ca, *cb, s, uint64_t(1) << 30, device());
    ASSERT_TRUE(chunked.isOk()) << chunked.status().toString();
    if (std::string(name) == "/a.obj") {
      // The OBJ's text holds the same doubles (17 digits), so even the file read back measures the same.
      auto obj = readMeshFile(dir.path() + name);
      ASSERT_TRUE(obj.isOk());
      whole = measureMeshes(*obj, *b, s, device());
    }
    expectSameMeasure(*chunked, *whole);
  }
  // Nothing left behind by the scratch files.
  size_t left = 0;
  for (const auto& e : std::filesystem::directory_iterator(dir.path()))
    left += e.path().filename().string().rfind("scanpress-scratch", 0) == 0;
  EXPECT_EQ(left, 0u);
}

TEST(ChunkedSurface, ContainerTilesMeasureAsTheWeldedDecode) {
  TempDir dir;
  const Mesh sphere = bumpy(5, 0.03);
  ASSERT_TRUE(writeMeshFile(dir.path() + "/in.ply", sphere).isOk());
  EncodeSettings e;
  e.input = dir.path() + "/in.ply";
  e.output = dir.path() + "/out.spz";
  e.tile_triangles = 2000;  // many tiles
  e.codec = "pm";
  e.codec_options.pm.max_error = 4;
  e.bits = 12;
  ASSERT_TRUE(encodeFile(e).isOk());
  auto tiles = ChunkedSurface::fromContainer(e.output);
  ASSERT_TRUE(tiles.isOk()) << tiles.status().toString();
  EXPECT_GT(tiles->chunks(), 5u);
  auto decoded = readSurfaceFile(e.output);
  ASSERT_TRUE(decoded.isOk());
  EXPECT_EQ(tiles->triangles(), decoded->triangles.size());
  MeasureSettings s;
  auto whole = measureMeshes(sphere, *decoded, s, device());
  auto chunked = measureChunked(ChunkedSurface::whole(sphere), *tiles, s, 1, device());
  ASSERT_TRUE(whole.isOk() && chunked.isOk());
  expectSameMeasure(*chunked, *whole);
  EXPECT_GT(whole->symmetric.rms, 0);  // a lossy encode: not a trivially equal zero
}

// Pixels that are background (245 gray) in `a` but not in `b`: holes of `a`.
size_t holes(const Image& a, const Image& b) {
  size_t n = 0;
  for (size_t i = 0; i < a.rgb.size(); i += 3) {
    const bool bg_a = a.rgb[i] == 245 && a.rgb[i + 1] == 245 && a.rgb[i + 2] == 245;
    const bool bg_b = b.rgb[i] == 245 && b.rgb[i + 1] == 245 && b.rgb[i + 2] == 245;
    n += bg_a && !bg_b;
  }
  return n;
}

// Pixels of two images that differ.
size_t differingPixels(const Image& a, const Image& b) {
  size_t n = 0;
  for (size_t i = 0; i < a.rgb.size(); i += 3)
    n += a.rgb[i] != b.rgb[i] || a.rgb[i + 1] != b.rgb[i + 1] || a.rgb[i + 2] != b.rgb[i + 2];
  return n;
}

TEST(ChunkedSurface, PicturesDrawnAChunkAtATimeAreTheWholeOnes) {
  Mesh colored = bumpy(4, 0.04);
  for (size_t v = 0; v < colored.positions.size(); ++v)
    colored.colors.push_back(Rgba8{uint8_t(v * 7), uint8_t(v * 13), uint8_t(v * 29), 255});
  colored.color_channels = 3;
  const Mesh reference = bumpy(5, 0.02);
  RenderSettings s;
  s.width = 240;
  s.height = 180;
  s.title = "chunks";
  auto whole = renderMesh(colored, s, device(), &reference);
  auto whole_colors = renderMesh(colored, s, device());
  ASSERT_TRUE(whole.isOk() && whole_colors.isOk());
  for (uint64_t run : {5, 300}) {
    const ChunkedSurface mesh = ChunkedSurface::pieces(colored, run), ref = ChunkedSurface::pieces(reference, 77);
    auto chunked = renderSurface(mesh, s, device(), &ref, 1);
    auto chunked_colors = renderSurface(mesh, s, device(), nullptr, 1);
    ASSERT_TRUE(chunked.isOk() && chunked_colors.isOk());
    EXPECT_EQ(chunked->scale_max, whole->scale_max);
    EXPECT_EQ(chunked->diagonal, whole->diagonal);
    // Only pixels whose ray meets an edge between two chunks' triangles may differ.
    EXPECT_LE(differingPixels(chunked->image, whole->image), 20u) << "run " << run;
    EXPECT_LE(differingPixels(chunked_colors->image, whole_colors->image), 20u) << "run " << run;
    EXPECT_GT(differingPixels(chunked_colors->image, chunked->image), 5000u);  // colors, not the heat map
    EXPECT_EQ(holes(chunked->image, whole->image), 0u);  // no ray slips between two chunks at their seam
    EXPECT_EQ(holes(chunked_colors->image, whole_colors->image), 0u);
  }
}

TEST(ChunkedSurface, CliMeasuresAndDrawsUnderABudget) {
  TempDir dir;
  synthFile(dir, "a.ply", 200000);  // about 3.8 MB: its estimate (40 MB) is over a 16M budget
  const std::string a = dir.path() + "/a.ply", spz = dir.path() + "/a.spz", b = dir.path() + "/b.ply";
  ASSERT_EQ(runScanpress("encode " + a + " " + spz + " --bits 11 --quiet"), 0);
  ASSERT_EQ(runScanpress("decode " + spz + " " + b + " --quiet"), 0);
  std::string in_memory, chunked, from_container;
  ASSERT_EQ(runScanpress("measure " + a + " " + b + " --json --memory-budget 0", &in_memory), 0);
  ASSERT_EQ(runScanpress("measure " + a + " " + b + " --json --memory-budget 16M --scratch-dir " + dir.path(),
                         &chunked),
            0);
  EXPECT_EQ(in_memory, chunked);
  ASSERT_EQ(runScanpress("measure " + a + " " + spz + " --json", &from_container), 0);
  const auto x = nlohmann::json::parse(in_memory), y = nlohmann::json::parse(from_container);
  // The container is measured at its cells' centres, the decoded file at their float rounding.
  EXPECT_NEAR(x["symmetric"]["rms"].get<double>(), y["symmetric"]["rms"].get<double>(),
              1e-4 * x["symmetric"]["rms"].get<double>());
  EXPECT_EQ(x["forward"]["samples"], y["forward"]["samples"]);
  ASSERT_EQ(runScanpress("render " + b + " " + dir.path() + "/whole.png --against " + a + " --memory-budget 0"), 0);
  ASSERT_EQ(runScanpress("render " + b + " " + dir.path() + "/chunks.png --against " + a + " --memory-budget 16M"), 0);
  ASSERT_EQ(runScanpress("render " + spz + " " + dir.path() + "/tiles.png --against " + a), 0);
  const Image whole = testing::decodePng(readBytes(dir.path() + "/whole.png"));
  const Image chunks = testing::decodePng(readBytes(dir.path() + "/chunks.png"));
  ASSERT_EQ(whole.width, 800);
  ASSERT_EQ(chunks.width, 800);
  EXPECT_LE(differingPixels(whole, chunks), 100u);
  EXPECT_EQ(holes(chunks, whole), 0u);
  // Errors name the file.
  std::string out;
  EXPECT_NE(runScanpress("measure " + a + " " + dir.path() + "/missing.spz", &out), 0);
  EXPECT_NE(runScanpress("measure " + a + " " + b + " --memory-budget 1M", &out), 0);
  // A container's tile must fit the index cache (half the budget), as decode refuses a tile over its budget.
  EXPECT_EQ(runScanpress("measure " + a + " " + spz + " --memory-budget 16M", &out), 2);
  EXPECT_NE(out.find("give --memory-budget"), std::string::npos) << out;
  writeBytes(dir.path() + "/bad.spz", "not a container at all, just some bytes that are long enough to be read");
  EXPECT_NE(runScanpress("render " + dir.path() + "/bad.spz " + dir.path() + "/bad.png", &out), 0);
  EXPECT_FALSE(std::filesystem::exists(dir.path() + "/bad.png"));
}

// A job's error picture under its memory budget: drawn a chunk at a time when the meshes would need more, the
// same picture as without a budget (up to edge pixels).
TEST(ChunkedSurface, JobErrorPictureUnderItsBudget) {
  TempDir dir;
  const std::string scan = synthFile(dir, "scan.ply", 200000);
  Image pictures[2];
  for (int budget : {0, 16}) {
    const std::string job = dir.path() + "/job" + std::to_string(budget) + ".json";
    writeBytes(job, "{\"inputs\": [\"" + scan + "\"], \"output\": {\"directory\": \"out" + std::to_string(budget) +
                        "\"}, \"memory_budget_mb\": " + std::to_string(budget) +
                        ", \"codec\": {\"bits\": 10}, \"measure\": {\"enabled\": true, \"render\": true, "
                        "\"render_size\": [300, 200], \"scale_max\": 0.001}}");
    std::string out;
    ASSERT_EQ(runScanpress("run " + job + " --quiet", &out), 0) << out;
    pictures[budget ? 1 : 0] =
        testing::decodePng(readBytes(dir.path() + "/out" + std::to_string(budget) + "/scan.error.png"));
  }
  ASSERT_EQ(pictures[0].width, 300);
  ASSERT_EQ(pictures[1].width, 300);
  EXPECT_LE(differingPixels(pictures[0], pictures[1]), 30u);
}

}  // namespace
}  // namespace scanpress
