// Scalar channels through files (issue 22 part 1): the bunny's confidence and intensity (float PLY properties)
// through encode and decode with every codec that carries them, in one tile and in many (welded across borders),
// in memory and out of core, compared with the input file's values vertex by vertex; prm resamples them; --no-scalars
// drops them; formats without scalars say so on decode.
#include <gtest/gtest.h>

#include <bit>
#include <cmath>
#include <filesystem>
#include <map>
#include <tuple>

#include "engine/container/container.h"
#include "jobs/commands.h"
#include "jobs/container_file.h"
#include "jobs/mesh_io/mesh_reader.h"
#include "jobs/pipeline.h"
#include "jobs_util.h"

namespace scanpress {
namespace {

using testing::kBunny;
using testing::TempDir;

// (grid cell, scalar row) of every vertex a triangle uses, distinct and sorted: what a lossless codec keeps.
std::vector<std::pair<Vec3u, std::vector<uint32_t>>> cellRows(const Mesh& m, const Grid& grid) {
  size_t stride = 0;
  for (const ScalarChannel& c : m.scalar_channels) stride += size_t(scalarTypeWords(c.type));
  std::vector<uint8_t> used(m.positions.size());
  for (const Triangle& t : m.triangles)
    for (uint32_t v : t) used[v] = 1;
  std::vector<std::pair<Vec3u, std::vector<uint32_t>>> out;
  for (size_t v = 0; v < m.positions.size(); ++v)
    if (used[v])
      out.push_back({grid.quantize(m.positions[v]),
                     std::vector<uint32_t>(m.scalars.begin() + ptrdiff_t(v * stride),
                                           m.scalars.begin() + ptrdiff_t((v + 1) * stride))});
  std::sort(out.begin(), out.end());
  out.erase(std::unique(out.begin(), out.end()), out.end());
  return out;
}

EncodeSettings scalarSettingsFor(const std::string& out, const std::string& codec) {
  return testing::encodeSettings(kBunny, out, codec);
}

TEST(ScalarFiles, BunnyConfidenceAndIntensityComeBackBitForBit) {
  TempDir dir;
  auto input = readMeshFile(kBunny);
  ASSERT_TRUE(input.isOk());
  ASSERT_EQ(input->scalar_channels,
            (std::vector<ScalarChannel>{{"confidence", ScalarType::kFloat32}, {"intensity", ScalarType::kFloat32}}));
  struct Case {
    const char* codec;
    uint64_t tile_triangles;
    uint64_t memory_budget;  // 0: in memory
  };
  for (const Case& c : {Case{"edgebreaker", 131072, 0}, Case{"kdtree", 6000, 0}, Case{"octree", 6000, 0},
                        Case{"store", 6000, 0}, Case{"pm", 6000, 0}, Case{"edgebreaker", 6000, uint64_t(6) << 20}}) {
    SCOPED_TRACE(std::string(c.codec) + ", " + std::to_string(c.tile_triangles) + " triangles per tile" +
                 (c.memory_budget ? ", out of core" : ""));
    EncodeSettings s = scalarSettingsFor(dir.file("b.spz"), c.codec);
    s.tile_triangles = c.tile_triangles;
    s.memory_budget = c.memory_budget;
    auto enc = encodeFile(s);
    ASSERT_TRUE(enc.isOk()) << enc.status().toString();
    EXPECT_EQ(enc->layout.scalars, input->scalar_channels);
    EXPECT_TRUE(enc->read.dropped.empty()) << describeDropped(enc->read.dropped);
    EXPECT_EQ(c.memory_budget != 0, enc->out_of_core);
    if (c.tile_triangles < 131072) {
      EXPECT_GT(enc->tiles.size(), 4u);
    }
    auto file = ContainerFile::open(s.output);
    ASSERT_TRUE(file.isOk());
    EXPECT_EQ(file->header().version, kContainerVersionScalars);
    DecodeSettings d;
    d.input = s.output;
    d.output = dir.file("b.ply");
    auto dec = decodeFile(d);
    ASSERT_TRUE(dec.isOk()) << dec.status().toString();
    EXPECT_TRUE(dec->dropped.empty());
    auto output = readMeshFile(d.output);
    ASSERT_TRUE(output.isOk());
    EXPECT_EQ(output->scalar_channels, input->scalar_channels);
    const auto want = cellRows(*input, file->header().grid), got = cellRows(*output, file->header().grid);
    ASSERT_EQ(got.size(), want.size());
    EXPECT_TRUE(got == want);
  }
}

// prm keeps them (resampled where it remeshes; with the bunny's noisy channels it keeps most tiles as they are, so
// this checks the channels come back within the input's ranges, not the resampling: Prm.ScalarChannels...);
// --no-scalars drops them on request and writes a version 1 container; decoding to a format without scalars lists
// them.
TEST(ScalarFiles, WhatIsDroppedIsSaid) {
  TempDir dir;
  EncodeSettings prm = scalarSettingsFor(dir.file("prm.spz"), "prm");
  prm.strict = true;
  auto r = encodeFile(prm);
  ASSERT_TRUE(r.isOk()) << r.status().toString();
  EXPECT_EQ(r->layout.scalars.size(), 2u);
  EXPECT_TRUE(r->read.dropped.empty()) << describeDropped(r->read.dropped);
  {
    auto input = readMeshFile(kBunny);
    ASSERT_TRUE(input.isOk());
    float lo[2] = {INFINITY, INFINITY}, hi[2] = {-INFINITY, -INFINITY};
    for (size_t i = 0; i < input->scalars.size(); ++i) {
      const float f = std::bit_cast<float>(input->scalars[i]);
      lo[i % 2] = std::min(lo[i % 2], f), hi[i % 2] = std::max(hi[i % 2], f);
    }
    auto back = testing::decodeAndReadBack(prm.output, dir.file("prm.ply"));
    ASSERT_TRUE(back.isOk()) << back.status().toString();
    ASSERT_EQ(back->scalar_channels, input->scalar_channels);
    ASSERT_EQ(back->scalars.size(), 2 * back->positions.size());
    for (size_t i = 0; i < back->scalars.size(); ++i) {
      const float f = std::bit_cast<float>(back->scalars[i]);
      EXPECT_TRUE(f >= lo[i % 2] && f <= hi[i % 2]) << i << ": " << f;
    }
  }

  EncodeSettings none = scalarSettingsFor(dir.file("none.spz"), "kdtree");
  none.keep_scalars = false;
  r = encodeFile(none);
  ASSERT_TRUE(r.isOk());
  EXPECT_TRUE(r->layout.scalars.empty());
  EXPECT_EQ(describeDropped(r->dropped_on_request), "vertex.confidence x 35947, vertex.intensity x 35947");
  auto file = ContainerFile::open(none.output);
  ASSERT_TRUE(file.isOk());
  EXPECT_EQ(file->header().version, kContainerVersion);

  EncodeSettings kept = scalarSettingsFor(dir.file("kept.spz"), "kdtree");
  ASSERT_TRUE(encodeFile(kept).isOk());
  DecodeSettings d;
  d.input = kept.output;
  d.output = dir.file("b.obj");
  auto dec = decodeFile(d);
  ASSERT_TRUE(dec.isOk()) << dec.status().toString();
  EXPECT_EQ(describeDropped(dec->dropped), "vertex.confidence x 34834, vertex.intensity x 34834");
}

// Decoding under a memory budget streams tile batch by tile batch: a container of many tiles with scalars decodes
// to PLY with its channels, byte for byte as in memory, and to OBJ (welded without them, the same triangles as in
// memory), which says it dropped them. The weld's keys and records of border vertices outlive their tiles: they
// hold their own copies of the scalar values (this runs under ASan in CI).
TEST(ScalarFiles, StreamedDecodeOfManyTilesWithScalars) {
  TempDir dir;
  EncodeSettings s = scalarSettingsFor(dir.file("t.spz"), "kdtree");
  s.tile_triangles = 4000;
  auto enc = encodeFile(s);
  ASSERT_TRUE(enc.isOk()) << enc.status().toString();
  ASSERT_GT(enc->tiles.size(), 8u);
  DecodeSettings d;
  d.input = s.output;
  d.output = dir.file("mem.obj");
  auto whole = decodeFile(d);
  ASSERT_TRUE(whole.isOk()) << whole.status().toString();
  EXPECT_FALSE(whole->streamed);
  d.output = dir.file("streamed.obj");
  d.memory_budget = 1 << 20;  // the in-memory decode needs about 6 MiB
  auto streamed = decodeFile(d);
  ASSERT_TRUE(streamed.isOk()) << streamed.status().toString();
  EXPECT_TRUE(streamed->streamed);
  EXPECT_EQ(describeDropped(streamed->dropped), "vertex.confidence x " + std::to_string(streamed->vertices) +
                                                    ", vertex.intensity x " + std::to_string(streamed->vertices));
  auto a = readMeshFile(dir.file("mem.obj")), b = readMeshFile(dir.file("streamed.obj"));
  ASSERT_TRUE(a.isOk() && b.isOk());
  EXPECT_EQ(a->triangles.size(), b->triangles.size());
  for (const char* ext : {".ply", ".ply.zst"}) {
    SCOPED_TRACE(ext);
    d.memory_budget = 0;
    d.output = dir.file(std::string("mem") + ext);
    whole = decodeFile(d);
    ASSERT_TRUE(whole.isOk()) << whole.status().toString();
    d.memory_budget = 1 << 20;
    d.output = dir.file(std::string("streamed") + ext);
    streamed = decodeFile(d);
    ASSERT_TRUE(streamed.isOk()) << streamed.status().toString();
    EXPECT_TRUE(streamed->streamed);
    EXPECT_TRUE(streamed->dropped.empty()) << describeDropped(streamed->dropped);
    EXPECT_EQ(whole->vertices, streamed->vertices);
    EXPECT_TRUE(testing::readText(dir.file(std::string("mem") + ext)) == testing::readText(d.output))
        << "the bytes differ";
  }
  auto back = readMeshFile(dir.file("streamed.ply"));
  ASSERT_TRUE(back.isOk()) << back.status().toString();
  EXPECT_EQ(back->scalar_channels.size(), 2u);
}

// --codec auto under a target with --strict: pm keeps the scalars too, so both compete, and at this loose target
// the simplified result wins with its scalars (before pm carried them, edgebreaker won here by default).
TEST(ScalarFiles, AutoUnderStrictKeepsTheScalars) {
  TempDir dir;
  EncodeSettings s = scalarSettingsFor(dir.file("auto.spz"), "auto");
  s.strict = true;
  testing::setRmsTarget(s, 1e-3);
  auto r = encodeFile(s);
  ASSERT_TRUE(r.isOk()) << r.status().toString();
  EXPECT_EQ(r->codec, "pm");
  EXPECT_EQ(r->layout.scalars.size(), 2u);
  EXPECT_TRUE(r->read.dropped.empty()) << describeDropped(r->read.dropped);
}

// Through the command line: the warning on decode to OBJ, and --no-scalars.
TEST(ScalarFiles, CommandLine) {
  TempDir dir;
  std::string out;
  ASSERT_EQ(testing::run("encode " + kBunny + " " + dir.file("a.spz") + " --codec edgebreaker", &out), 0) << out;
  EXPECT_EQ(out.find("warning"), std::string::npos) << out;
  ASSERT_EQ(testing::run("decode " + dir.file("a.spz") + " " + dir.file("a.obj") + " --quiet", &out), 0) << out;
  EXPECT_NE(out.find("warning: " + dir.file("a.spz") + " holds vertex.confidence"), std::string::npos) << out;
  ASSERT_EQ(testing::run("encode " + kBunny + " " + dir.file("b.spz") + " --no-scalars", &out), 0) << out;
  EXPECT_LT(std::filesystem::file_size(dir.file("b.spz")), std::filesystem::file_size(dir.file("a.spz")));
}

}  // namespace
}  // namespace scanpress
