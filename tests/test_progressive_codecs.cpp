// The lossless codecs: the progressive `kdtree` and `octree` and the single-rate `edgebreaker`: lossless round trips on meshes of every kind (manifold,
// boundaries, non-manifold, soups, duplicates, isolated and coincident vertices), every progressive level decodes
// to a valid mesh, truncated and corrupted payloads fail cleanly (decoded here without the container's checksums).
#include <gtest/gtest.h>

#include <random>

#include "engine/codecs/codec.h"
#include "engine/octahedral.h"
#include "engine/quantize.h"
#include "engine/shapes.h"
#include "test_util.h"

namespace scanpress {
namespace {

using testing::quantized;
using testing::rawMesh;

class Progressive : public ::testing::TestWithParam<CodecId> {
 protected:
  const CodecInfo& codec() const { return *findCodec(GetParam()); }
};

EncodedTile encode(const CodecInfo& codec, const TileContext& ctx, const QuantizedMesh& q) {
  auto e = encodeMesh(codec, ctx, q);
  EXPECT_TRUE(e.isOk()) << e.status().toString();
  return e.isOk() ? std::move(e).value() : EncodedTile{};
}

// Decodes and checks the result is the input (triangles with orientation and multiplicity, attributes).
void expectRoundTrip(const CodecInfo& codec, const TileContext& ctx, const QuantizedMesh& q) {
  const EncodedTile enc = encode(codec, ctx, q);
  auto d = codec.decode(ctx, payloadVersion(codec, enc), enc.payload, limitsOf(enc.decoded));
  ASSERT_TRUE(d.isOk()) << d.status().toString();
  EXPECT_EQ(d->triangles.size(), q.triangles.size());
  EXPECT_TRUE(testing::cornerMultiset(*d, ctx.layout.normal_bits) ==
              testing::cornerMultiset(q, ctx.layout.normal_bits));
  // What the encoder said the decoder yields is what it yields.
  const TileSummary got = summarize(*d);
  EXPECT_EQ(got.vertices, enc.decoded.vertices);
  EXPECT_EQ(got.faces, enc.decoded.faces);
  EXPECT_EQ(got.lo, enc.decoded.lo);
  EXPECT_EQ(got.hi, enc.decoded.hi);
  // A limit one below either count is refused before decoding.
  if (enc.decoded.vertices > 0) {
    EXPECT_EQ(codec
                  .decode(ctx, payloadVersion(codec, enc), enc.payload,
                          DecodeLimits{enc.decoded.vertices - 1, enc.decoded.faces})
                  .status()
                  .code(),
              ErrorCode::kMalformed);
  }
  if (enc.decoded.faces > 0) {
    EXPECT_EQ(codec
                  .decode(ctx, payloadVersion(codec, enc), enc.payload,
                          DecodeLimits{enc.decoded.vertices, enc.decoded.faces - 1})
                  .status()
                  .code(),
              ErrorCode::kMalformed);
  }
  // Every input position comes back (isolated vertices included).
  auto positions = [](const QuantizedMesh& m) {
    std::vector<Vec3u> p = m.positions;
    std::sort(p.begin(), p.end());
    p.erase(std::unique(p.begin(), p.end()), p.end());
    return p;
  };
  EXPECT_EQ(positions(*d), positions(q));
}

TEST_P(Progressive, ClosedManifolds) {
  const TileContext ctx{12, {}};
  expectRoundTrip(codec(), ctx, quantized(testing::octahedron(), 12));
  for (int levels : {0, 1, 3, 5}) expectRoundTrip(codec(), ctx, quantized(icosphere(levels), 12));
  expectRoundTrip(codec(), TileContext{16, {}}, quantized(icosphere(4), 16));
}

TEST_P(Progressive, EmptySingleAndIsolated) {
  const TileContext ctx{10, {}};
  expectRoundTrip(codec(), ctx, QuantizedMesh{});
  expectRoundTrip(codec(), ctx, rawMesh({{5, 6, 7}}, {}));
  expectRoundTrip(codec(), ctx, rawMesh({{0, 0, 0}, {1023, 1023, 1023}, {1, 0, 0}}, {}));
  // A triangle plus isolated vertices, one of them far away.
  expectRoundTrip(codec(), ctx, rawMesh({{0, 0, 0}, {9, 0, 0}, {0, 9, 0}, {500, 3, 3}, {4, 4, 4}}, {{0, 1, 2}}));
}

TEST_P(Progressive, NonManifoldBoundariesAndSoups) {
  const TileContext ctx{10, {}};
  // Three triangles on one edge; a bow-tie vertex; an open strip with boundary.
  expectRoundTrip(codec(), ctx,
                  rawMesh({{0, 0, 0}, {10, 0, 0}, {5, 9, 0}, {5, 0, 9}, {5, 3, 3}}, {{0, 1, 2}, {1, 0, 3}, {0, 1, 4}}));
  expectRoundTrip(codec(), ctx,
                  rawMesh({{10, 10, 10}, {0, 0, 0}, {0, 20, 0}, {20, 0, 20}, {20, 20, 20}}, {{0, 1, 2}, {0, 3, 4}}));
  std::vector<Vec3u> strip;
  std::vector<Triangle> st;
  for (uint32_t i = 0; i < 40; ++i) strip.push_back({i * 7, (i % 2) * 11, 3 + (i * 13) % 5});
  for (uint32_t i = 0; i + 2 < 40; ++i) st.push_back(i % 2 ? Triangle{i, i + 2, i + 1} : Triangle{i, i + 1, i + 2});
  expectRoundTrip(codec(), ctx, rawMesh(strip, st));
  // A random soup: unshared vertices, random positions, overlapping triangles.
  std::mt19937 rng(7);
  std::uniform_int_distribution<uint32_t> coord(0, 1023);
  QuantizedMesh soup;
  for (uint32_t t = 0; t < 300; ++t) {
    for (int c = 0; c < 3; ++c) soup.positions.push_back({coord(rng), coord(rng), coord(rng)});
    soup.triangles.push_back({3 * t, 3 * t + 1, 3 * t + 2});
  }
  expectRoundTrip(codec(), ctx, soup);
  // Random triangles over few shared vertices: heavily non-manifold.
  QuantizedMesh dense;
  for (int v = 0; v < 40; ++v) dense.positions.push_back({coord(rng), coord(rng), coord(rng)});
  std::uniform_int_distribution<uint32_t> pick(0, 39);
  while (dense.triangles.size() < 400) {
    Triangle t{pick(rng), pick(rng), pick(rng)};
    if (t[0] != t[1] && t[1] != t[2] && t[0] != t[2]) dense.triangles.push_back(t);
  }
  expectRoundTrip(codec(), ctx, dense);
}

TEST_P(Progressive, DuplicatesOrientationAndCoincidentVertices) {
  const TileContext ctx{10, {}};
  // The same triangle twice, and once more reversed; an inconsistently oriented neighbour.
  expectRoundTrip(codec(), ctx,
                  rawMesh({{0, 0, 0}, {10, 0, 0}, {0, 10, 0}, {10, 10, 0}},
                          {{0, 1, 2}, {0, 1, 2}, {0, 2, 1}, {1, 3, 2}, {1, 2, 3}, {1, 2, 3}}));
  // Flipped halves of an icosphere.
  QuantizedMesh q = quantized(icosphere(2), 10);
  for (size_t t = 0; t < q.triangles.size(); t += 3) std::swap(q.triangles[t][1], q.triangles[t][2]);
  expectRoundTrip(codec(), ctx, q);
  // Vertices sharing a cell: without attributes they merge (same triangles over positions).
  expectRoundTrip(codec(), ctx,
                  rawMesh({{0, 0, 0}, {10, 0, 0}, {0, 10, 0}, {0, 0, 0}, {0, 0, 10}}, {{0, 1, 2}, {3, 2, 4}}));
  // With attributes they stay apart: coincident vertices with different normals and colors.
  TileContext actx{10, {8, 3}};
  QuantizedMesh a = rawMesh({{0, 0, 0}, {10, 0, 0}, {0, 10, 0}, {0, 0, 0}, {0, 0, 10}, {0, 0, 0}},
                            {{0, 1, 2}, {3, 2, 4}, {5, 4, 1}});
  for (int v = 0; v < 6; ++v) {
    a.normals.push_back({uint16_t(10 + v), uint16_t(200 - v)});
    a.colors.push_back({uint8_t(v), uint8_t(2 * v), uint8_t(3 * v), 255});
  }
  expectRoundTrip(codec(), actx, a);
}

TEST_P(Progressive, LargeFanAndAttributes) {
  const TileContext ctx{16, {}};
  QuantizedMesh fan;
  fan.positions.push_back({32768, 32768, 100});
  const uint32_t n = 3000;
  for (uint32_t i = 0; i < n; ++i) {
    const double a = 6.283185307179586 * i / n;
    fan.positions.push_back({uint32_t(32768 + 30000 * std::cos(a)), uint32_t(32768 + 30000 * std::sin(a)), 0});
  }
  for (uint32_t i = 0; i < n; ++i) fan.triangles.push_back({0, 1 + i, 1 + (i + 1) % n});
  expectRoundTrip(codec(), ctx, fan);

  Mesh sphere = icosphere(3);
  for (const auto& p : sphere.positions) {
    sphere.normals.push_back({float(p[0]), float(p[1]), float(p[2])});
    sphere.colors.push_back({uint8_t(128 + 100 * p[0]), uint8_t(128 + 100 * p[1]), 7, 255});
  }
  sphere.color_channels = 3;
  const AttributeLayout layout{12, 3};
  expectRoundTrip(codec(), TileContext{14, layout}, quantized(sphere, 14, layout));
}

// Every level of a small mesh decodes, from a payload cut at that level's end, to a valid mesh: vertices on the
// grid, triangles with three distinct corners; vertex counts grow with the level; the last level is lossless.
TEST_P(Progressive, EveryLevelDecodesToAValidMesh) {
  if (!codec().progressive()) GTEST_SKIP() << "single-rate codec: no levels";
  const TileContext ctx{12, {12, 0}};
  Mesh sphere = icosphere(4);
  for (const auto& p : sphere.positions) sphere.normals.push_back({float(p[0]), float(p[1]), float(p[2])});
  const QuantizedMesh q = quantized(sphere, 12, ctx.layout);
  const EncodedTile enc = encode(codec(), ctx, q);
  const auto& bytes = enc.payload;
  const DecodeLimits lim = limitsOf(enc.decoded);
  auto levels = codec().levels(ctx, payloadVersion(codec(), enc), bytes, lim);
  ASSERT_TRUE(levels.isOk()) << levels.status().toString();
  ASSERT_EQ(levels->back().level, 12u);
  EXPECT_EQ(levels->back().end_bytes, bytes.size());
  // Each level says what it means: cells of 2^(bits - L) grid cells, the last one complete; the encoder returned
  // the same list.
  ASSERT_EQ(levels->size(), enc.levels.size());
  for (size_t i = 0; i < levels->size(); ++i) {
    const CodecLevel& lv = (*levels)[i];
    EXPECT_EQ(lv.level, enc.levels[i].level);
    EXPECT_EQ(lv.end_bytes, enc.levels[i].end_bytes);
    EXPECT_EQ(lv.kind, LevelKind::kCells);
    EXPECT_EQ(lv.cell_bits, 12 - lv.level);
    EXPECT_EQ(lv.complete, i + 1 == levels->size());
  }
  EXPECT_EQ(describeLevel(levels->front()), "cells of 2^" + std::to_string(levels->front().cell_bits) + " grid cells");
  EXPECT_EQ(describeLevel(levels->back()), "cells of 2^0 grid cells (complete)");
  size_t last_vertices = 0;
  for (const auto& lv : *levels) {
    SCOPED_TRACE(lv.level);
    const std::span<const uint8_t> prefix(bytes.data(), lv.end_bytes);
    auto m = codec().decode_level(ctx, payloadVersion(codec(), enc), prefix, lv.level, lim);
    ASSERT_TRUE(m.isOk()) << m.status().toString();
    EXPECT_TRUE(validateTile(ctx, *m).isOk());
    for (const auto& t : m->triangles) {
      EXPECT_NE(t[0], t[1]);
      EXPECT_NE(t[1], t[2]);
      EXPECT_NE(t[0], t[2]);
    }
    EXPECT_GE(m->positions.size(), last_vertices);
    last_vertices = m->positions.size();
    // The same level from the whole payload.
    auto full = codec().decode_level(ctx, payloadVersion(codec(), enc), bytes, lv.level, lim);
    ASSERT_TRUE(full.isOk());
    EXPECT_EQ(full->positions, m->positions);
    EXPECT_EQ(full->triangles, m->triangles);
    if (lv.level < 12 && lv.end_bytes > 0) {  // one byte short of the level is an error, not a crash
      auto cut = codec().decode_level(ctx, payloadVersion(codec(), enc),
                                      std::span<const uint8_t>(bytes.data(), lv.end_bytes - 1), lv.level, lim);
      if (lv.level > levels->front().level) {
        EXPECT_FALSE(cut.isOk());
      }
    }
  }
  EXPECT_TRUE(testing::cornerMultiset(*codec().decode_level(ctx, payloadVersion(codec(), enc), bytes, 12, lim), 12) ==
              testing::cornerMultiset(q, 12));
  // Coarse levels look like the mesh: by level 6 it has most of its sphere.
  auto l6 = codec().decode_level(ctx, payloadVersion(codec(), enc), bytes, 6, lim);
  ASSERT_TRUE(l6.isOk());
  EXPECT_GT(l6->triangles.size(), 100u);
}

TEST_P(Progressive, EveryTruncationFailsCleanly) {
  const TileContext ctx{12, {}};
  const EncodedTile enc = encode(codec(), ctx, quantized(icosphere(2), 12));
  const auto& bytes = enc.payload;
  const DecodeLimits lim = limitsOf(enc.decoded);
  for (size_t n = 0; n < bytes.size(); ++n) {
    auto d = codec().decode(ctx, payloadVersion(codec(), enc), std::span<const uint8_t>(bytes.data(), n), lim);
    EXPECT_FALSE(d.isOk()) << "a payload cut to " << n << " of " << bytes.size() << " bytes decoded";
  }
  EXPECT_EQ(codec().decode(ctx, codec().version + 1, bytes, lim).status().code(), ErrorCode::kUnknownVersion);
}

// Corrupted payloads (no checksum in the way): errors or some valid mesh, never a crash, hang or bad index
// (the sanitizer build checks memory).
TEST_P(Progressive, RandomCorruptionsNeverCrash) {
  const TileContext ctx{12, {12, 3}};
  Mesh sphere = icosphere(2);
  for (const auto& p : sphere.positions) {
    sphere.normals.push_back({float(p[0]), float(p[1]), float(p[2])});
    sphere.colors.push_back({1, 2, 3, 255});
  }
  sphere.color_channels = 3;
  const EncodedTile enc = encode(codec(), ctx, quantized(sphere, 12, ctx.layout));
  const auto& bytes = enc.payload;
  const DecodeLimits lim = limitsOf(enc.decoded);
  std::mt19937 rng(11);
  int failures = 0;
  for (int trial = 0; trial < 2000; ++trial) {
    auto b = bytes;
    const int flips = 1 + trial % 4;
    for (int f = 0; f < flips; ++f) b[rng() % b.size()] ^= uint8_t(1 + rng() % 255);
    const uint32_t level = trial % 3 == 0 ? uint32_t(rng() % 13) : 12u;
    auto d = codec().progressive() ? codec().decode_level(ctx, payloadVersion(codec(), enc), b, level, lim)
                                   : codec().decode(ctx, payloadVersion(codec(), enc), b, lim);
    if (!d.isOk()) {
      ++failures;
    } else {
      EXPECT_TRUE(validateTile(ctx, *d).isOk());
    }
  }
  EXPECT_GT(failures, 0);
}

TEST_P(Progressive, RejectsWhatItCannotCode) {
  const TileContext ctx{10, {}};
  // Two corners in one cell (quantizeMesh drops these triangles before any codec sees them).
  EXPECT_EQ(encodeMesh(codec(), ctx, rawMesh({{0, 0, 0}, {0, 0, 0}, {1, 1, 1}}, {{0, 1, 2}})).status().code(),
            ErrorCode::kInvalidArgument);
  EXPECT_EQ(encodeMesh(codec(), ctx, rawMesh({{0, 0, 0}, {1, 0, 0}, {1, 1, 1}}, {{0, 1, 3}})).status().code(),
            ErrorCode::kInvalidArgument);
  EXPECT_EQ(encodeMesh(codec(), ctx, rawMesh({{0, 0, 0}, {1, 0, 0}, {1024, 1, 1}}, {{0, 1, 2}})).status().code(),
            ErrorCode::kInvalidArgument);
}

INSTANTIATE_TEST_SUITE_P(Codecs, Progressive, ::testing::Values(CodecId::kKdtree, CodecId::kOctree),
                         [](const ::testing::TestParamInfo<CodecId>& info) {
  return std::string(findCodec(info.param)->name);
});

INSTANTIATE_TEST_SUITE_P(SingleRate, Progressive, ::testing::Values(CodecId::kEdgebreaker),
                         [](const ::testing::TestParamInfo<CodecId>& info) {
  return std::string(findCodec(info.param)->name);
});

}  // namespace
}  // namespace scanpress
