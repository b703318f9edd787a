// What the encode pipeline takes in (issue 18, items 2 and 3): the grid spans the vertices that triangles use, so
// a stray vertex cannot destroy a scan; a scan whose quantization drops more than 0.1% of its triangles fails with
// exit 2 unless allowed; a point cloud is encoded as points (never an empty success) and decodes to a PLY of points.
#include <gtest/gtest.h>

#include <algorithm>
#include <random>
#include <tuple>

#include <nlohmann/json.hpp>
#include <vector>

#include "engine/octahedral.h"
#include "jobs/commands.h"
#include "jobs/batch.h"
#include "jobs/config.h"
#include "jobs/mesh_io/mesh_reader.h"
#include "jobs/measure.h"
#include "jobs/mesh_io/mesh_writer.h"
#include "jobs/pipeline.h"
#include "jobs_util.h"
#include "spatial/surface_index.h"

namespace scanpress {
namespace {

using testing::kBunny;
using testing::run;

Mesh bunny() {
  auto m = readMeshFile(kBunny);
  EXPECT_TRUE(m.isOk()) << m.status().toString();
  return m.isOk() ? std::move(m).value() : Mesh();
}

// The bunny with one vertex no triangle uses, far away: at (1000, 1000, 1000) (the bunny spans about 0.15).
Mesh bunnyWithStray() {
  Mesh m = bunny();
  m.positions.push_back({1000, 1000, 1000});
  m.scalars.resize(m.scalars.size() + m.scalars.size() / (m.positions.size() - 1), 0);  // its confidence and intensity
  return m;
}

EncodeSettings settingsFor(const std::string& in, const std::string& out, const std::string& codec = "store") {
  EncodeSettings s;
  s.input = in;
  s.output = out;
  s.codec = codec;
  return s;
}

// Item 2: the stray vertex neither stretches the grid (every triangle of the bunny kept, as without it) nor the
// diagonal of the relative error; in memory (the survey keeps the mesh) and streamed (a small memory budget makes
// the survey drop it, and the vertices are read once more).
TEST(Ingest, StrayVertexKeepsTheTrianglesAndTheDiagonal) {
  testing::TempDir dir;
  const std::string clean = dir.file("bunny.ply"), stray = dir.file("stray.ply");
  ASSERT_TRUE(writePly(clean, bunny()).isOk());
  ASSERT_TRUE(writePly(stray, bunnyWithStray()).isOk());
  EncodeSettings base = settingsFor(clean, dir.file("clean.spz"));
  base.measure.enabled = true;
  auto want = encodeFile(base);
  ASSERT_TRUE(want.isOk()) << want.status().toString();
  EXPECT_EQ(want->faces, 69451u);
  EXPECT_LT(want->diagonal, 1.0);
  for (uint64_t budget : {uint64_t(0), uint64_t(3) << 20}) {
    SCOPED_TRACE(budget);
    EncodeSettings s = settingsFor(stray, dir.file("stray.spz"));
    s.measure.enabled = true;
    s.memory_budget = budget;
    auto got = encodeFile(s);
    ASSERT_TRUE(got.isOk()) << got.status().toString();
    EXPECT_EQ(got->faces, want->faces);
    EXPECT_EQ(got->quantize.degenerate_triangles, want->quantize.degenerate_triangles);
    EXPECT_EQ(got->quantize.unreferenced_vertices, want->quantize.unreferenced_vertices + 1);
    EXPECT_EQ(got->grid.origin, want->grid.origin);
    EXPECT_EQ(got->grid.cell, want->grid.cell);
    EXPECT_DOUBLE_EQ(got->diagonal, want->diagonal);
    // The relative error is tiny because the encode is good, not because the diagonal is huge.
    const ErrorStats f = statsOf(got->forward);
    EXPECT_LT(f.max / got->diagonal, 1e-4);
  }
  // measure too: the diagonal of the original is its triangles' box.
  auto with = readMeshFile(stray);
  ASSERT_TRUE(with.isOk());
  auto device = EmbreeDevice::create();
  ASSERT_TRUE(device.isOk());
  auto m = measureMeshes(*with, bunny(), MeasureSettings(), *device);
  ASSERT_TRUE(m.isOk()) << m.status().toString();
  EXPECT_DOUBLE_EQ(m->diagonal, want->diagonal);
}

// Item 2: dropping more than 0.1% of the triangles fails (exit 2, how many, --bits), unless allowed. The bunny with
// one far vertex that a triangle uses: the grid must span it, and at 16 bits the bunny is a few cells wide.
TEST(Ingest, TooManyDegenerateTrianglesFailUnlessAllowed) {
  testing::TempDir dir;
  Mesh m = bunnyWithStray();
  m.triangles.push_back({0, 1, static_cast<uint32_t>(m.positions.size() - 1)});
  const std::string in = dir.file("outlier.ply");
  ASSERT_TRUE(writePly(in, m).isOk());
  EncodeSettings s = settingsFor(in, dir.file("b.spz"));
  auto r = encodeFile(s);
  ASSERT_FALSE(r.isOk());
  EXPECT_EQ(r.status().code(), ErrorCode::kLimitExceeded);
  EXPECT_EQ(exitCodeFor(r.status().code()), 2);
  EXPECT_NE(r.status().message().find("of 69452 triangles degenerate"), std::string::npos) << r.status().message();
  EXPECT_NE(r.status().message().find("--bits"), std::string::npos);
  EXPECT_FALSE(std::filesystem::exists(s.output));
  s.allow_degenerate = true;
  r = encodeFile(s);
  ASSERT_TRUE(r.isOk()) << r.status().toString();
  EXPECT_GT(double(r->quantize.degenerate_triangles), 0.5 * 69452);
  EXPECT_EQ(r->faces + r->quantize.degenerate_triangles, 69452u);
  s.allow_degenerate = false;
  s.bits = 24;  // what the message suggests
  r = encodeFile(s);
  ASSERT_TRUE(r.isOk()) << r.status().toString();
  EXPECT_LE(double(r->quantize.degenerate_triangles), 0.001 * 69452);
  // At most 0.1% passes: the bunny at 8 bits drops 68 of 69451 (0.098%).
  EncodeSettings coarse = settingsFor(kBunny, dir.file("coarse.spz"));
  coarse.bits = 8;
  r = encodeFile(coarse);
  ASSERT_TRUE(r.isOk()) << r.status().toString();
  EXPECT_EQ(r->quantize.degenerate_triangles, 68u);

  std::string out;
  const std::string args = "encode '" + in + "' '" + dir.file("c.spz") + "'";
  EXPECT_EQ(run(args, &out), 2) << out;
  EXPECT_NE(out.find("triangles degenerate"), std::string::npos) << out;
  EXPECT_NE(out.find("--allow-degenerate"), std::string::npos) << out;
  EXPECT_EQ(run(args + " --allow-degenerate --quiet", &out), 0) << out;

  // The job key, and the resume fingerprint (only when set: earlier fingerprints stay valid).
  auto job = parseJobConfig(R"({"inputs": ["a.ply"], "codec": {"allow_degenerate": true}})", "job.json");
  ASSERT_TRUE(job.isOk()) << job.status().toString();
  EXPECT_TRUE(job->encode.allow_degenerate);
  EncodeSettings plain = settingsFor("a.ply", "a.spz"), allowed = plain;
  allowed.allow_degenerate = true;
  EXPECT_NE(settingsFingerprint(plain), settingsFingerprint(allowed));
}

// A point cloud with normals and colors: points at distinct random positions.
Mesh pointCloud(size_t n) {
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> u(-2.0, 3.0);
  Mesh m;
  for (size_t i = 0; i < n; ++i) {
    m.positions.push_back({u(rng), 0.5 * u(rng), 0.25 * u(rng)});
    Vec3f nrm{float(u(rng)), float(u(rng)), float(u(rng))};
    const float len = std::sqrt(nrm[0] * nrm[0] + nrm[1] * nrm[1] + nrm[2] * nrm[2]);
    for (float& c : nrm) c /= len;
    m.normals.push_back(nrm);
    m.colors.push_back({uint8_t(rng()), uint8_t(rng()), uint8_t(rng()), 255});
  }
  m.color_channels = 3;
  return m;
}

// Whether two point sets are the same points: positions and colors equal, normals the same directions (codes may
// differ on the octahedral fold border), matched by position and color (distinct in these tests).
bool samePoints(const QuantizedMesh& a, const QuantizedMesh& b, int normal_bits) {
  if (a.positions.size() != b.positions.size()) return false;
  auto sorted = [](const QuantizedMesh& m) {
    std::vector<std::tuple<Vec3u, Rgba8, OctNormal>> p;
    for (size_t i = 0; i < m.positions.size(); ++i) p.emplace_back(m.positions[i], m.colors[i], m.normals[i]);
    std::sort(p.begin(), p.end());
    return p;
  };
  const auto x = sorted(a), y = sorted(b);
  std::vector<OctNormal> nx, ny;
  for (size_t i = 0; i < x.size(); ++i) {
    if (std::get<0>(x[i]) != std::get<0>(y[i]) || std::get<1>(x[i]) != std::get<1>(y[i])) return false;
    nx.push_back(std::get<2>(x[i]));
    ny.push_back(std::get<2>(y[i]));
  }
  return testing::sameNormalDirections(nx, ny, normal_bits);
}

// The points of `m` on `grid` with `layout`'s attributes (what an encode must keep).
QuantizedMesh onGrid(const Mesh& m, const Grid& grid, const AttributeLayout& layout) {
  QuantizedMesh q;
  for (size_t i = 0; i < m.positions.size(); ++i) {
    q.positions.push_back(grid.quantize(m.positions[i]));
    q.normals.push_back(encodeOctahedral(m.normals[i], layout.normal_bits));
    q.colors.push_back(m.colors[i]);
  }
  return q;
}

// Item 3: every codec that codes isolated vertices encodes a point cloud's points on the grid with their
// attributes, over several tiles; decode writes a PLY of points that reads back the same.
TEST(Ingest, PointCloudRoundTripsThroughEveryCodec) {
  testing::TempDir dir;
  const size_t n = 6000;
  const std::string in = dir.file("cloud.ply");
  ASSERT_TRUE(writePly(in, pointCloud(n)).isOk());
  auto cloud = readMeshFile(in);  // positions as the PLY holds them (floats)
  ASSERT_TRUE(cloud.isOk()) << cloud.status().toString();
  for (const char* codec : {"store", "kdtree", "octree"}) {
    SCOPED_TRACE(codec);
    EncodeSettings s = settingsFor(in, dir.file(std::string(codec) + ".spz"), codec);
    s.tile_triangles = 1024;   // several tiles: points are binned by position
    s.measure.enabled = true;  // not measured (no surface), and no failure either
    auto enc = encodeFile(s);
    ASSERT_TRUE(enc.isOk()) << enc.status().toString();
    EXPECT_TRUE(enc->point_cloud);
    EXPECT_FALSE(enc->measured);
    EXPECT_EQ(enc->vertices, n);
    EXPECT_EQ(enc->faces, 0u);
    EXPECT_GT(enc->tiles.size(), 2u);
    EXPECT_EQ(enc->tile_vertices, n);
    EXPECT_EQ(enc->quantize.unreferenced_vertices, 0u);

    ContainerHeader header;
    auto decoded = decodeContainer(s.output, std::nullopt, &header);
    ASSERT_TRUE(decoded.isOk()) << decoded.status().toString();
    EXPECT_TRUE(decoded->triangles.empty());
    ASSERT_TRUE(header.layout.hasNormals());
    ASSERT_TRUE(header.layout.hasColors());
    const QuantizedMesh want = onGrid(*cloud, header.grid, header.layout);
    EXPECT_TRUE(samePoints(*decoded, want, header.layout.normal_bits));

    DecodeSettings ds;
    ds.input = s.output;
    ds.output = dir.file(std::string(codec) + ".ply");
    auto dec = decodeFile(ds);
    ASSERT_TRUE(dec.isOk()) << dec.status().toString();
    EXPECT_EQ(dec->vertices, n);
    EXPECT_EQ(dec->faces, 0u);
    auto back = readMeshFile(ds.output);
    ASSERT_TRUE(back.isOk()) << back.status().toString();
    EXPECT_TRUE(back->triangles.empty());
    ASSERT_EQ(back->positions.size(), n);
    ASSERT_EQ(back->normals.size(), n);
    ASSERT_EQ(back->colors.size(), n);
    // The PLY's points, on the container's grid again.
    EXPECT_TRUE(samePoints(onGrid(*back, header.grid, header.layout), want, header.layout.normal_bits));
  }
}

// Item 3 through the CLI: encode, info, decode to PLY, read back; measure says a point cloud has no surface.
TEST(Ingest, PointCloudThroughTheCli) {
  testing::TempDir dir;
  const size_t n = 3000;
  const std::string in = dir.file("cloud.ply"), spz = dir.file("cloud.spz"), ply = dir.file("back.ply");
  ASSERT_TRUE(writePly(in, pointCloud(n)).isOk());
  std::string out;
  ASSERT_EQ(run("encode '" + in + "' '" + spz + "' --codec kdtree --report '" + dir.file("r.json") + "'", &out), 0)
      << out;
  EXPECT_NE(out.find("3000 vertices, 0 faces"), std::string::npos) << out;
  std::ifstream report(dir.file("r.json"));
  const auto j = nlohmann::json::parse(report);
  EXPECT_EQ(j["point_cloud"], true);
  EXPECT_EQ(j["vertices"], n);
  ASSERT_EQ(run("info '" + spz + "' --json", &out), 0) << out;
  const auto info = nlohmann::json::parse(out);
  EXPECT_EQ(info["vertices"], n);
  EXPECT_EQ(info["faces"], 0);
  ASSERT_EQ(run("decode '" + spz + "' '" + ply + "' --quiet", &out), 0) << out;
  auto back = readMeshFile(ply);
  ASSERT_TRUE(back.isOk()) << back.status().toString();
  EXPECT_EQ(back->positions.size(), n);
  EXPECT_EQ(back->normals.size(), n);
  EXPECT_EQ(back->colors.size(), n);
  EXPECT_TRUE(back->triangles.empty());
  EXPECT_EQ(run("measure '" + in + "' '" + ply + "'", &out), 2) << out;
  EXPECT_NE(out.find("point cloud"), std::string::npos) << out;
}

// Out of core the tile pass reads the input again (KeptTriangles) instead of a spill file: it must see exactly the
// triangles (or points) the ingest pass kept, in the same order, so the bytes equal an in-memory encode's. Inputs
// where that is easy to get wrong: many triangles made degenerate by a coarse grid, a stray vertex, a point cloud,
// a text format, a compressed file.
TEST(Ingest, OutOfCoreEncodesTheSameTrianglesAsInMemory) {
  testing::TempDir dir;
  Mesh points = bunny();
  points.triangles.clear();
  ASSERT_TRUE(writePly(dir.file("stray.ply"), bunnyWithStray()).isOk());
  ASSERT_TRUE(writePly(dir.file("points.ply"), points).isOk());
  ASSERT_TRUE(writeObj(dir.file("bunny.obj"), bunny()).isOk());
  struct Case {
    std::string input;
    int bits;
  };
  std::vector<Case> cases = {{dir.file("stray.ply"), 8}, {dir.file("points.ply"), 12}};
#if !defined(__SANITIZE_ADDRESS__)  // the slow sanitizer build: the binary PLYs only
  cases.push_back({dir.file("bunny.obj"), 16});
  cases.push_back({kBunny, 11});
#endif
  for (const Case& c : cases) {
    SCOPED_TRACE(c.input + " at " + std::to_string(c.bits) + " bits");
    auto encode = [&](const std::string& out, uint64_t budget) {
      EncodeSettings s = settingsFor(c.input, dir.file(out), "edgebreaker");
      s.bits = c.bits;
      s.allow_degenerate = true;
      s.tile_triangles = 4096;
      s.memory_budget = budget;
      return encodeFile(s);
    };
    auto memory = encode("memory.spz", 0);
    auto disk = encode("disk.spz", 3u << 20);
    ASSERT_TRUE(memory.isOk()) << memory.status().toString();
    ASSERT_TRUE(disk.isOk()) << disk.status().toString();
    EXPECT_FALSE(memory->out_of_core);
    EXPECT_TRUE(disk->out_of_core);
    EXPECT_GT(disk->tiles.size(), 2u);
    EXPECT_EQ(disk->faces, memory->faces);
    if (c.bits == 8) {
      EXPECT_GT(disk->quantize.degenerate_triangles, 20u);  // the coarse grid drops some
    }
    EXPECT_TRUE(testing::readBytes(dir.file("disk.spz")) == testing::readBytes(dir.file("memory.spz")));
  }
}

}  // namespace
}  // namespace scanpress
