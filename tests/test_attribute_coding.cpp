// Predicted normals and colors (engine/codecs/attributes.h, version 2 of kdtree, octree and edgebreaker): the
// integer octahedral projection against the float one, the fold and its preimages on every code, exact round trips
// of every normal code at every precision (inward normals, codes on the folded border, twins at one position,
// isolated vertices, point clouds), RGB and RGBA, truncations, and the prediction actually predicting.
#include <gtest/gtest.h>

#include <map>
#include <random>
#include <tuple>

#include "engine/codecs/attributes.h"
#include "engine/codecs/codec.h"
#include "engine/octahedral.h"
#include "engine/quantize.h"
#include "engine/shapes.h"
#include "test_util.h"

namespace scanpress {
namespace {

using hierarchy::foldCode;
using hierarchy::foldPreimages;
using hierarchy::octahedralOfSum;
using hierarchy::Sum3;

constexpr uint64_t kPinnedHash = 0xa5bd5863bbfd8dbaull;  // AngleWeightedNormalsArePinnedBitForBit

TEST(AttributeCoding, IntegerProjectionMatchesTheFloatOne) {
  std::mt19937_64 rng(7);
  std::uniform_int_distribution<int64_t> coord(-(int64_t(1) << 40), int64_t(1) << 40);
  for (int bits : {4, 8, 10, 12, 16}) {
    const int m = (1 << (bits - 1)) - 1;
    for (int i = 0; i < 20000; ++i) {
      Sum3 s{coord(rng), coord(rng), coord(rng)};
      if (i % 7 == 0) s[i % 3] = 0;  // on the coordinate planes
      if (s[0] == 0 && s[1] == 0 && s[2] == 0) continue;
      const auto code = octahedralOfSum(s, bits);
      ASSERT_LE(std::abs(code[0]) + 0, m);
      ASSERT_LE(std::abs(code[1]) + 0, m);
      // The float projection (encodeOctahedral's rounding, without its best-of-four search) agrees within a code.
      const double l1 = std::fabs(double(s[0])) + std::fabs(double(s[1])) + std::fabs(double(s[2]));
      double u = double(s[0]) / l1, v = double(s[1]) / l1;
      if (s[2] < 0) {
        const double fu = (1 - std::fabs(v)) * (u >= 0 ? 1 : -1), fv = (1 - std::fabs(u)) * (v >= 0 ? 1 : -1);
        u = fu, v = fv;
      }
      EXPECT_LE(std::fabs(code[0] - u * m), 0.5 + 1e-9) << bits;
      EXPECT_LE(std::fabs(code[1] - v * m), 0.5 + 1e-9) << bits;
      // Scaling the sum does not move the code.
      EXPECT_EQ(octahedralOfSum(Sum3{s[0] * 3, s[1] * 3, s[2] * 3}, bits), code);
    }
  }
}

// The predicted normal against an independent angle-weighted normal (std::atan2, long double) on random fans,
// degenerate triangles among them.
TEST(AttributeCoding, AngleWeightedNormalMatchesAnIndependentOne) {
  std::mt19937 rng(3);
  std::uniform_int_distribution<uint32_t> coord(0, (1u << 24) - 1);
  for (int trial = 0; trial < 2000; ++trial) {
    std::vector<Vec3u> pos = {{coord(rng), coord(rng), coord(rng)}};
    std::vector<Triangle> tris;
    const int k = 1 + int(rng() % 8);
    for (int i = 0; i < k; ++i) {
      pos.push_back({coord(rng), coord(rng), coord(rng)});
      pos.push_back(i % 5 == 4 ? pos.back() : Vec3u{coord(rng), coord(rng), coord(rng)});  // some zero-area
      const uint32_t a = uint32_t(pos.size() - 2), b = uint32_t(pos.size() - 1);
      // v at every corner position, the winding kept
      tris.push_back(i % 3 == 0 ? Triangle{0, a, b} : i % 3 == 1 ? Triangle{a, b, 0} : Triangle{b, 0, a});
    }
    const Sum3 s = hierarchy::scaledSum(hierarchy::angleWeightedNormals(pos, tris)[0]);
    long double want[3] = {0, 0, 0};
    for (const auto& t : tris) {
      const int c = t[0] == 0 ? 0 : t[1] == 0 ? 1 : 2;
      long double e1[3], e2[3];
      for (int a = 0; a < 3; ++a) {
        e1[a] = (long double)pos[t[(c + 1) % 3]][a] - pos[t[c]][a];
        e2[a] = (long double)pos[t[(c + 2) % 3]][a] - pos[t[c]][a];
      }
      const long double n[3] = {e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2],
                                e1[0] * e2[1] - e1[1] * e2[0]};
      const long double len = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
      if (len == 0) continue;
      const long double angle = std::atan2(len, e1[0] * e2[0] + e1[1] * e2[1] + e1[2] * e2[2]);
      for (int a = 0; a < 3; ++a) want[a] += n[a] / len * angle;
    }
    const long double wl = std::sqrt(want[0] * want[0] + want[1] * want[1] + want[2] * want[2]);
    const long double got[3] = {(long double)s[0], (long double)s[1], (long double)s[2]};
    const long double gl = std::sqrt(got[0] * got[0] + got[1] * got[1] + got[2] * got[2]);
    if (wl < 1e-2) continue;  // opposite triangles cancelling: no direction to compare
    ASSERT_GT(gl, 0);
    const long double dot = (got[0] * want[0] + got[1] * want[1] + got[2] * want[2]) / (gl * wl);
    // The arctangent is within 1e-5 rad per triangle: the direction within that over the sum's length.
    const long double allowed = std::min(1e-5L * k / wl + 1e-9L, 0.5L);
    EXPECT_GE(dot, std::cos(allowed)) << trial;
  }
}

// The predicted normals bit for bit on a fixed mesh: a compiler, flag or machine that computes them differently
// would decode version 2 payloads to other normals. If this fails, the build is not format-compatible.
TEST(AttributeCoding, AngleWeightedNormalsArePinnedBitForBit) {
  const Mesh sphere = icosphere(3);
  const Grid grid = *makeGrid(boundingBox(sphere), 16);
  const QuantizedMesh q = *quantizeMesh(sphere, grid, {}, nullptr);
  uint64_t hash = 1469598103934665603ull;  // FNV-1a over the scaled sums' 128-bit values
  for (const auto& d : hierarchy::angleWeightedNormals(q.positions, q.triangles)) {
    const Sum3 s = hierarchy::scaledSum(d);
    for (const auto& c : s)
      for (int byte = 0; byte < 16; ++byte)
        hash = (hash ^ uint8_t(uint64_t(c >> (8 * byte)) & 0xff)) * 1099511628211ull;
  }
  EXPECT_EQ(hash, kPinnedHash) << std::hex << hash;
}

TEST(AttributeCoding, ColorLevelsRoundTripAndRoundToTheNearest) {
  for (int bits = 1; bits <= 8; ++bits) {
    const int top = (1 << bits) - 1;
    for (int level = 0; level <= top; ++level) EXPECT_EQ(colorLevel(colorOfLevel(level, bits), bits), level);
    for (int v = 0; v < 256; ++v) {
      const int level = colorLevel(uint8_t(v), bits);
      ASSERT_LE(level, top);
      EXPECT_LE(std::abs(level * 255.0 / top - v), 255.0 / top / 2 + 1e-9) << bits << " " << v;
    }
  }
  for (int v = 0; v < 256; ++v) EXPECT_EQ(colorOfLevel(colorLevel(uint8_t(v), 8), 8), v);
}

TEST(AttributeCoding, FoldIsTheZMirrorAndItsPreimagesAreExact) {
  for (int bits : {4, 5, 8}) {
    const int m = (1 << (bits - 1)) - 1;
    for (int u = -m; u <= m; ++u)
      for (int v = -m; v <= m; ++v) {
        const std::array<int, 2> c{u, v};
        const auto f = foldCode(c, m);
        ASSERT_LE(std::abs(f[0]) + 0, m);
        ASSERT_LE(std::abs(f[1]) + 0, m);
        // The fold mirrors the direction through z = 0.
        const Vec3f d = decodeOctahedral({uint16_t(u + m), uint16_t(v + m)}, bits);
        const Vec3f e = decodeOctahedral({uint16_t(f[0] + m), uint16_t(f[1] + m)}, bits);
        EXPECT_NEAR(d[0], e[0], 1e-6);
        EXPECT_NEAR(d[1], e[1], 1e-6);
        EXPECT_NEAR(d[2], -e[2], 1e-6);
        // c is among the preimages of its fold, and every preimage folds onto it.
        std::array<std::array<int, 2>, 4> pre;
        const int count = foldPreimages(f, m, pre);
        ASSERT_GE(count, 1);
        bool found = false;
        for (int i = 0; i < count; ++i) {
          EXPECT_EQ(foldCode(pre[i], m), f);
          found |= pre[i] == c;
        }
        EXPECT_TRUE(found) << u << "," << v;
        // Off the square's border the fold is its own inverse.
        if (std::abs(u) < m && std::abs(v) < m) {
          EXPECT_EQ(count, 1);
          EXPECT_EQ(foldCode(f, m), c);
        }
      }
  }
}

// The distinct vertices as (position, normal code, color): what an exact round trip keeps, whatever the vertex
// order (the codecs merge vertices equal in all three).
std::vector<std::tuple<Vec3u, OctNormal, Rgba8>> vertexMultiset(const QuantizedMesh& m) {
  std::vector<std::tuple<Vec3u, OctNormal, Rgba8>> out;
  for (size_t i = 0; i < m.positions.size(); ++i)
    out.emplace_back(m.positions[i], m.normals.empty() ? OctNormal{0, 0} : m.normals[i],
                     m.colors.empty() ? Rgba8{0, 0, 0, 0} : m.colors[i]);
  std::sort(out.begin(), out.end());
  out.erase(std::unique(out.begin(), out.end()), out.end());
  return out;
}

// A sphere whose normals run through every code of the square (when there are fewer codes than vertices), half of
// them pointing inward, with smooth colors, twins at one position with another normal and color, and an isolated
// vertex.
QuantizedMesh attributedSphere(int normal_bits, int channels, bool point_cloud) {
  const Mesh sphere = icosphere(4);
  const Grid grid = *makeGrid(boundingBox(sphere), 12);
  QuantizedMesh q = *quantizeMesh(sphere, grid, {}, nullptr);
  const int m = (1 << (normal_bits - 1)) - 1;
  const int64_t codes = int64_t(2 * m + 1) * (2 * m + 1);
  const bool every_code = codes <= int64_t(q.positions.size());
  std::mt19937 rng(normal_bits * 10 + channels);
  for (size_t i = 0; i < q.positions.size(); ++i) {
    const Vec3d& p = sphere.positions[i];
    const float s = (i % 3 == 0) ? -1.f : 1.f;  // inward on a third
    OctNormal code = every_code ? OctNormal{uint16_t(i % (2 * m + 1)), uint16_t((i / (2 * m + 1)) % (2 * m + 1))}
                                : encodeOctahedral({s * float(p[0]), s * float(p[1]), s * float(p[2])}, normal_bits);
    if (!every_code && i % 4 == 1) {  // codes on the square's border (two codes of one direction), spread along it
      const uint32_t j = uint32_t(i / 4), along = (j / 4 * 7919u) % uint32_t(2 * m + 1);
      const uint16_t edge = (j % 2) ? uint16_t(2 * m) : uint16_t(0);
      code = (j % 4) < 2 ? OctNormal{edge, uint16_t(along)} : OctNormal{uint16_t(along), edge};
    }
    q.normals.push_back(code);
    q.colors.push_back({uint8_t(128 + 120 * p[0]), uint8_t(128 + 100 * p[1] + (rng() % 5)), uint8_t(rng()),
                        uint8_t(channels == 4 ? 200 + rng() % 50 : 255)});
  }
  for (int k = 0; k < 20; ++k) {  // twins: a vertex's position with another normal and color, in a triangle
    const uint32_t twin = uint32_t(q.positions.size());
    const auto t = q.triangles[size_t(k) * 37];
    q.positions.push_back(q.positions[t[0]]);
    q.normals.push_back({uint16_t((q.normals[t[0]][0] + 3) % (2 * m + 1)), q.normals[t[0]][1]});
    q.colors.push_back({0, 255, 0, 255});
    q.triangles.push_back({twin, t[2], t[1]});
  }
  q.positions.push_back({2048, 2048, 2048});  // isolated, inside
  q.normals.push_back({uint16_t(2 * m), uint16_t(2 * m)});
  q.colors.push_back({1, 2, 3, 255});
  if (point_cloud) q.triangles.clear();
  return q;
}

class AttributeRoundTrip : public ::testing::TestWithParam<CodecId> {
 protected:
  const CodecInfo& codec() const { return *findCodec(GetParam()); }
};

TEST_P(AttributeRoundTrip, EveryNormalPrecisionAndColorLayoutIsExact) {
  for (int normal_bits : {4, 5, 8, 10, 12, 16})
    for (int channels : {0, 3, 4})
      for (bool point_cloud : {false, true}) {
        if (point_cloud && GetParam() == CodecId::kEdgebreaker) continue;  // refuses a tile without triangles
        SCOPED_TRACE(std::to_string(normal_bits) + " normal bits, " + std::to_string(channels) + " channels" +
                     (point_cloud ? ", point cloud" : ""));
        const AttributeLayout layout{uint8_t(normal_bits), uint8_t(channels)};
        QuantizedMesh q = attributedSphere(normal_bits, channels, point_cloud);
        if (!channels) q.colors.clear();
        for (auto& c : q.colors)
          if (channels == 3) c[3] = 255;
        const TileContext ctx{12, layout};
        auto enc = encodeMesh(codec(), ctx, q);
        ASSERT_TRUE(enc.isOk()) << enc.status().toString();
        auto d = codec().decode(ctx, payloadVersion(codec(), *enc), enc->payload, limitsOf(enc->decoded));
        ASSERT_TRUE(d.isOk()) << d.status().toString();
        const auto got = vertexMultiset(*d), want = vertexMultiset(q);
        ASSERT_EQ(got.size(), want.size());
        for (size_t i = 0; i < got.size(); ++i)
          ASSERT_TRUE(got[i] == want[i])
              << i << ": normal " << std::get<1>(got[i])[0] << "," << std::get<1>(got[i])[1] << " want "
              << std::get<1>(want[i])[0] << "," << std::get<1>(want[i])[1] << " color " << int(std::get<2>(got[i])[0])
              << " want " << int(std::get<2>(want[i])[0]);
        EXPECT_TRUE(testing::cornerMultiset(*d, normal_bits) == testing::cornerMultiset(q, normal_bits));
      }
}

TEST_P(AttributeRoundTrip, EveryTruncationFailsCleanly) {
  const AttributeLayout layout{10, 4};
  const QuantizedMesh q = attributedSphere(10, 4, false);
  const TileContext ctx{12, layout};
  auto enc = encodeMesh(codec(), ctx, q);
  ASSERT_TRUE(enc.isOk()) << enc.status().toString();
  const auto& bytes = enc->payload;
  // Every cut in the first and last 256 bytes (counts and the coder's start; the attributes' end), a stride of 13
  // through the rest (each cut decodes the whole tile before it fails: every byte would take minutes under ASan).
  for (size_t n = 0; n < bytes.size();
       n += (n < 256 || n + 256 >= bytes.size() ? testing::sampleStride() : 13 * testing::sampleStride())) {
    auto d = codec().decode(ctx, payloadVersion(codec(), *enc), std::span<const uint8_t>(bytes.data(), n),
                            limitsOf(enc->decoded));
    EXPECT_FALSE(d.isOk()) << "a payload cut to " << n << " of " << bytes.size() << " bytes decoded";
  }
}

// Colors at fewer bits: snapped to their levels by quantization, coded as levels, back exactly; a color off its
// levels is refused.
TEST_P(AttributeRoundTrip, ColorLevelsAtEveryPrecision) {
  for (int color_bits = 1; color_bits <= 8; ++color_bits)
    for (int channels : {3, 4}) {
      SCOPED_TRACE(std::to_string(color_bits) + " color bits, " + std::to_string(channels) + " channels");
      AttributeLayout layout{10, uint8_t(channels)};
      layout.color_bits = uint8_t(color_bits);
      QuantizedMesh q = attributedSphere(10, channels, false);
      for (auto& c : q.colors) c = quantizeColor(c, layout);
      const TileContext ctx{12, layout};
      auto enc = encodeMesh(codec(), ctx, q);
      ASSERT_TRUE(enc.isOk()) << enc.status().toString();
      auto d = codec().decode(ctx, payloadVersion(codec(), *enc), enc->payload, limitsOf(enc->decoded));
      ASSERT_TRUE(d.isOk()) << d.status().toString();
      EXPECT_TRUE(vertexMultiset(*d) == vertexMultiset(q));
      if (color_bits < 8) {
        QuantizedMesh off = q;
        off.colors[7][1] = uint8_t(colorOfLevel(1, color_bits) + 1);  // between two levels (no level is 1 above one)
        if (quantizeColor(off.colors[7], layout) != off.colors[7]) {
          auto refused = encodeMesh(codec(), ctx, off);
          ASSERT_FALSE(refused.isOk());
          EXPECT_EQ(refused.status().code(), ErrorCode::kInvalidArgument);
        }
      }
    }
}

// Encoders refuse a normal that is not an octahedral code (2^bits - 1: quantization never writes it) instead of
// coding another one.
TEST_P(AttributeRoundTrip, RefusesANormalAboveTheOctahedralCodes) {
  QuantizedMesh q = attributedSphere(10, 3, false);
  q.normals[5] = {1023, 100};
  auto enc = encodeMesh(codec(), TileContext{12, {10, 3}}, q);
  ASSERT_FALSE(enc.isOk());
  EXPECT_EQ(enc.status().code(), ErrorCode::kInvalidArgument);
}

// Bytes changed in the attributes (the payload's tail): an error or some valid mesh, never a crash or a bad index
// (the sanitizer build checks memory).
TEST_P(AttributeRoundTrip, CorruptedAttributesFailCleanly) {
  const QuantizedMesh q = attributedSphere(12, 4, false);
  const TileContext ctx{12, {12, 4}};
  auto enc = encodeMesh(codec(), ctx, q);
  ASSERT_TRUE(enc.isOk()) << enc.status().toString();
  std::mt19937 rng(11);
  const size_t n = enc->payload.size(), tail = n / 3;
  for (int trial = 0; trial < testing::sampled(300); ++trial) {
    std::vector<uint8_t> bad = enc->payload;
    for (int k = 0; k < 1 + trial % 4; ++k) bad[n - 1 - rng() % tail] ^= uint8_t(1 + rng() % 255);
    auto d = codec().decode(ctx, payloadVersion(codec(), *enc), bad, limitsOf(enc->decoded));
    if (d.isOk()) {
      EXPECT_TRUE(validateTile(ctx, *d).isOk());
    }
  }
}

// On a smooth sphere with its own normals and colors the predictions hold: well below the raw 48 bits per vertex
// (normals at 12 bits, RGB); a broken predictor (a wrong sign, a wrong vertex) costs about the raw bits.
TEST_P(AttributeRoundTrip, PredictionsPredict) {
  const Mesh with = testing::coloredIcosphere(5);
  const Grid grid = *makeGrid(boundingBox(with), 14);
  const AttributeLayout layout{12, 3};
  const QuantizedMesh q = *quantizeMesh(with, grid, layout, nullptr);
  QuantizedMesh bare = q;
  bare.normals.clear();
  bare.colors.clear();
  auto full = encodeMesh(codec(), TileContext{14, layout}, q);
  auto geometry = encodeMesh(codec(), TileContext{14, {}}, bare);
  ASSERT_TRUE(full.isOk() && geometry.isOk());
  const double bits_per_vertex = 8.0 * double(full->payload.size() - geometry->payload.size()) /
                                 double(q.positions.size());
  EXPECT_LT(bits_per_vertex, 24.0) << "normals and colors (raw: 48 bits) cost " << bits_per_vertex
                                   << " bits per vertex";
}

void expectCoarseLevelsShowTheTilesOwnAttributes(const CodecInfo& codec, const AttributeLayout& layout) {
  SCOPED_TRACE(std::to_string(layout.normal_bits) + " normal bits, " + std::to_string(layout.color_channels) +
               " channels");
  QuantizedMesh q = attributedSphere(layout.hasNormals() ? layout.normal_bits : 10, 4, false);
  if (!layout.hasNormals()) q.normals.clear();
  if (!layout.hasColors()) q.colors.clear();
  for (auto& c : q.colors)
    if (layout.color_channels == 3) c[3] = 255;
  const TileContext ctx{12, layout};
  auto enc = encodeMesh(codec, ctx, q);
  ASSERT_TRUE(enc.isOk()) << enc.status().toString();
  auto levels = codec.levels(ctx, payloadVersion(codec, *enc), enc->payload, limitsOf(enc->decoded));
  ASSERT_TRUE(levels.isOk());
  const uint32_t n = uint32_t(q.positions.size());  // distinct points: twins differ in their attributes
  const uint32_t limit = std::max<uint32_t>(64, n / 16);
  int last_coded = -1;
  size_t checked = 0;
  for (size_t i = 1; i < levels->size(); ++i) {  // the root level has no segment: its one vertex derives them
    const CodecLevel& l = (*levels)[i];
    if (l.complete) continue;
    SCOPED_TRACE("level " + std::to_string(l.level));
    auto d = codec.decode_level(ctx, payloadVersion(codec, *enc), std::span(enc->payload.data(), l.end_bytes), l.level,
                                limitsOf(enc->decoded));
    ASSERT_TRUE(d.isOk()) << d.status().toString();
    ASSERT_EQ(d->normals.size(), layout.hasNormals() ? d->positions.size() : 0u);
    ASSERT_EQ(d->colors.size(), layout.hasColors() ? d->positions.size() : 0u);
    if (d->positions.size() <= limit) last_coded = int(l.level);
    ASSERT_GE(last_coded, 0) << "the first levels are coded";
    // Version 4 (the sphere's twins differ: cut edges; creases.h): a vertex by a crease or seam may show a value
    // chosen among its ancestors' (one within the range of its corners' points' values), a point of the tile's.
    const int within = payloadVersion(codec, *enc) >= 4 ? 0 : last_coded;
    EXPECT_EQ(testing::verticesShowingNoPointOfTheirCell(q, *d, 12, within), 0u)
        << "of " << d->positions.size() << " vertices show a normal and color of no point in their cell at level "
        << within;
    checked += d->positions.size();
  }
  EXPECT_GT(checked, 1000u);
  EXPECT_GE(last_coded, int((*levels)[1].level) + 1) << "two levels or more code their births";
}

// Version 3 (kdtree, octree): every vertex of a coarse level shows the normal and color of a point of the tile in its
// cell, not ones derived from its triangles, decoded from the level's prefix alone. Past the last level whose births
// are coded (the last with at most max(64, N / 16) vertices, FORMAT.md) a vertex shows those of a point in its
// ancestor's cell at that level. The sphere's colors are random in two channels and a third of its normals point
// inward: derived attributes, or a vertex showing another cell's point, fail.
TEST_P(AttributeRoundTrip, CoarseLevelsShowTheTilesOwnAttributes) {
  if (!codec().progressive()) GTEST_SKIP() << codec().name << " is single-rate";
  for (const AttributeLayout& layout : {AttributeLayout{10, 4}, AttributeLayout{0, 3}, AttributeLayout{12, 0}})
    expectCoarseLevelsShowTheTilesOwnAttributes(codec(), layout);
}

// A tile whose points share one grid position (different attributes: its root cube is the last level's cell)
// decodes at every level: one vertex with derived attributes before the last.
TEST_P(AttributeRoundTrip, ATileAtOneGridPositionDecodesAtEveryLevel) {
  if (!codec().progressive()) GTEST_SKIP() << codec().name << " is single-rate";
  QuantizedMesh q;
  q.positions = {{5, 6, 7}, {5, 6, 7}};
  q.normals = {{1, 2}, {3, 4}};
  q.colors = {{1, 2, 3, 255}, {4, 5, 6, 255}};
  const TileContext ctx{12, {10, 3}};
  auto enc = encodeMesh(codec(), ctx, q);
  ASSERT_TRUE(enc.isOk()) << enc.status().toString();
  for (uint32_t level : {0u, 5u, 11u}) {
    auto d = codec().decode_level(ctx, payloadVersion(codec(), *enc), enc->payload, level, limitsOf(enc->decoded));
    ASSERT_TRUE(d.isOk()) << "level " << level << ": " << d.status().toString();
    ASSERT_EQ(d->positions.size(), 1u);
    EXPECT_EQ(d->positions[0], (Vec3u{5, 6, 7}));
    EXPECT_EQ(d->normals.size(), 1u);
    EXPECT_EQ(d->colors.size(), 1u);
  }
  auto d = codec().decode(ctx, payloadVersion(codec(), *enc), enc->payload, limitsOf(enc->decoded));
  ASSERT_TRUE(d.isOk()) << d.status().toString();
  EXPECT_TRUE(vertexMultiset(*d) == vertexMultiset(q));
}

std::vector<CodecId> predictingCodecs() { return {CodecId::kKdtree, CodecId::kOctree, CodecId::kEdgebreaker}; }

INSTANTIATE_TEST_SUITE_P(Codecs, AttributeRoundTrip, ::testing::ValuesIn(predictingCodecs()),
                         [](const ::testing::TestParamInfo<CodecId>& info) {
  return std::string(findCodec(info.param)->name);
});

}  // namespace
}  // namespace scanpress
