// Codec `pm` on real scans (every level decodes, the last is the scan after quantization and welding) and through
// the CLI: a multi-tile encode decodes crack-free at every --level (tile borders are locked, so seams weld).
#include <gtest/gtest.h>

#include <filesystem>
#include <map>

#include <nlohmann/json.hpp>

#include "engine/codecs/codec.h"
#include "engine/quantize.h"
#include "engine/shapes.h"
#include "jobs/mesh_io/mesh_reader.h"
#include "jobs/mesh_io/mesh_writer.h"
#include "jobs_util.h"

namespace scanpress {
namespace {

std::vector<testing::PosTriangle> weldedTriangles(const QuantizedMesh& m) {
  std::vector<testing::PosTriangle> out;
  for (const auto& t : testing::triangleMultiset(m))
    if (t[0] != t[1] && t[1] != t[2] && t[0] != t[2]) out.push_back(t);
  return out;
}

TEST(PmScans, EveryLevelOfRealScansDecodes) {
  const CodecInfo& pm = *findCodec(CodecId::kPm);
#if defined(__SANITIZE_ADDRESS__)
  // The unoptimized sanitizer build takes minutes per large scan; the Release suite runs all three.
  for (const char* file : {"bun_zipper.ply.zst"}) {
#else
  for (const char* file : {"bun_zipper.ply.zst", "igea.ply.zst", "rs1_normals.ply.zst"}) {
#endif
    SCOPED_TRACE(file);
    const std::string path = testing::sharedDataDir() + "/" + file;
    if (!std::filesystem::exists(path)) {
      std::printf("shared data not found: %s (set SCANPRESS_DATA); skipped\n", path.c_str());
      continue;
    }
    auto mesh = readMeshFile(path);
    ASSERT_TRUE(mesh.isOk()) << mesh.status().toString();
    const TileContext ctx{16, {}};
    auto grid = makeGrid(boundingBox(*mesh), ctx.bits);
    auto q = quantizeMesh(*mesh, *grid, ctx.layout, nullptr);
    ASSERT_TRUE(q.isOk());
    for (double ratio : {1.0, 0.1}) {
      SCOPED_TRACE(ratio);
      CodecOptions options;
      if (ratio < 1) options.pm.max_error = 1e30, options.pm.ratio = ratio;
      auto enc = encodeMesh(pm, ctx, *q, options);
      ASSERT_TRUE(enc.isOk()) << enc.status().toString();
      const DecodeLimits limits = limitsOf(enc->decoded);
      uint64_t prev = 0;
      for (const CodecLevel& l : enc->levels) {
        auto d = pm.decode_level(ctx, payloadVersion(pm, *enc), std::span(enc->payload).first(l.end_bytes), l.level,
                                 limits);
        ASSERT_TRUE(d.isOk()) << d.status().toString();
        EXPECT_EQ(d->positions.size(), l.vertices);
        EXPECT_GE(l.vertices, prev);
        prev = l.vertices;
      }
      auto d = pm.decode(ctx, payloadVersion(pm, *enc), enc->payload, limits);
      ASSERT_TRUE(d.isOk()) << d.status().toString();
      if (ratio == 1.0) {
        EXPECT_TRUE(weldedTriangles(*d) == weldedTriangles(*q)) << "the last level is not the scan";
      } else {
        EXPECT_LE(double(d->triangles.size()), ratio * double(q->triangles.size()) + 2);
      }
    }
  }
}

// Edges (as position pairs) with exactly one incident triangle, after welding by position.
size_t openEdges(const Mesh& m) {
  std::map<std::pair<Vec3d, Vec3d>, int> count;
  for (const auto& t : m.triangles)
    for (int i = 0; i < 3; ++i) {
      Vec3d a = m.positions[t[i]], b = m.positions[t[(i + 1) % 3]];
      if (b < a) std::swap(a, b);
      ++count[{a, b}];
    }
  size_t open = 0;
  for (const auto& [e, c] : count) open += c == 1;
  return open;
}

TEST(PmCli, MultiTileDecodesCrackFreeAtEveryLevel) {
  testing::TempDir dir;
  const Mesh sphere = icosphere(5);
  const std::string input = dir.file("sphere.ply");
  ASSERT_TRUE(writeMeshFile(input, sphere, WriteOptions{}).isOk());
  const std::string spz = dir.file("sphere.spz");
  std::string out;
  ASSERT_EQ(testing::runScanpress("encode '" + input + "' '" + spz +
                                      "' --codec pm --bits 14 --tile-triangles 2048 --quiet",
                                  &out),
            0)
      << out;
  ASSERT_EQ(testing::runScanpress("info '" + spz + "' --json --verify", &out), 0) << out;
  const auto info = nlohmann::json::parse(out);
  ASSERT_GE(info["tiles"].size(), 4u);
  const size_t levels = info["levels"].size();
  ASSERT_GE(levels, 3u);
  for (size_t l = 0; l < levels; ++l) {
    SCOPED_TRACE(l);
    const std::string ply = dir.file("l" + std::to_string(l) + ".ply");
    ASSERT_EQ(testing::runScanpress("decode '" + spz + "' '" + ply + "' --level " + std::to_string(l), &out), 0) << out;
    auto m = readMeshFile(ply);
    ASSERT_TRUE(m.isOk()) << m.status().toString();
    EXPECT_GT(m->triangles.size(), 0u);
    EXPECT_EQ(openEdges(*m), 0u) << "level " << l << " has cracks";
  }
  const std::string full = dir.file("full.ply");
  ASSERT_EQ(testing::runScanpress("decode '" + spz + "' '" + full + "'", &out), 0) << out;
  auto m = readMeshFile(full);
  ASSERT_TRUE(m.isOk());
  EXPECT_EQ(m->triangles.size(), sphere.triangles.size());
  EXPECT_EQ(openEdges(*m), 0u);
}

}  // namespace
}  // namespace scanpress
