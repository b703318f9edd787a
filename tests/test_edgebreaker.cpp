// Codec `edgebreaker`: the inputs that exercise its traversal and its cut into manifold pieces (handles, a
// non-orientable strip, fins on an edge, vertices shared by separate fans, holes, many components), and hostile
// headers. The lossless-codec suite (test_progressive_codecs.cpp) runs the common round trips, truncations and
// corruptions on it too.
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "engine/codecs/codec.h"
#include "engine/io/bytes.h"
#include "engine/quantize.h"
#include "engine/shapes.h"
#include "test_util.h"

namespace scanpress {
namespace {

const CodecInfo& codec() { return *findCodec(CodecId::kEdgebreaker); }

// Encodes, decodes and compares corners (positions and attributes of every triangle, with orientation and
// multiplicity) with the input's.
void expectEdgebreakerRoundTrip(const TileContext& ctx, const QuantizedMesh& q) {
  auto enc = encodeMesh(codec(), ctx, q);
  ASSERT_TRUE(enc.isOk()) << enc.status().toString();
  EXPECT_TRUE(codec().floor.admits(ctx.layout, enc->decoded.vertices, enc->decoded.faces, enc->payload.size()));
  auto d = codec().decode(ctx, payloadVersion(codec(), *enc), enc->payload, limitsOf(enc->decoded));
  ASSERT_TRUE(d.isOk()) << d.status().toString();
  EXPECT_EQ(d->triangles.size(), q.triangles.size());
  EXPECT_TRUE(testing::cornerMultiset(*d, ctx.layout.normal_bits) ==
              testing::cornerMultiset(q, ctx.layout.normal_bits));
  EXPECT_EQ(summarize(*d).vertices, enc->decoded.vertices);
}

// A torus of n x m quads split in two (genus 1: the traversal merges two border loops).
QuantizedMesh torus(uint32_t n, uint32_t m, int genus_copies = 1) {
  QuantizedMesh q;
  for (int g = 0; g < genus_copies; ++g) {
    const uint32_t base = uint32_t(q.positions.size());
    for (uint32_t i = 0; i < n; ++i)
      for (uint32_t j = 0; j < m; ++j) {
        const double u = 6.283185307179586 * i / n, v = 6.283185307179586 * j / m;
        const double r = 300 + 100 * std::cos(v);
        q.positions.push_back({uint32_t(1000 + 1000 * g + r * std::cos(u)), uint32_t(1000 + r * std::sin(u)),
                               uint32_t(1000 + 100 * std::sin(v))});
      }
    auto at = [&](uint32_t i, uint32_t j) { return base + (i % n) * m + (j % m); };
    for (uint32_t i = 0; i < n; ++i)
      for (uint32_t j = 0; j < m; ++j) {
        q.triangles.push_back({at(i, j), at(i + 1, j), at(i + 1, j + 1)});
        q.triangles.push_back({at(i, j), at(i + 1, j + 1), at(i, j + 1)});
      }
  }
  return q;
}

TEST(Edgebreaker, HandlesAndManyComponents) {
  const TileContext ctx{12, {}};
  expectEdgebreakerRoundTrip(ctx, torus(24, 12));
  expectEdgebreakerRoundTrip(ctx, torus(7, 5, 3));
  // 200 separate tetrahedra and single triangles.
  QuantizedMesh many;
  for (uint32_t c = 0; c < 200; ++c) {
    const uint32_t b = uint32_t(many.positions.size());
    const uint32_t x = 10 + 19 * (c % 100), y = 10 + 400 * (c / 100);
    many.positions.insert(many.positions.end(), {{x, y, 5}, {x + 9, y, 5}, {x, y + 9, 5}, {x, y, 14}});
    many.triangles.push_back({b, b + 2, b + 1});
    if (c % 2) {
      many.triangles.push_back({b, b + 1, b + 3});
      many.triangles.push_back({b + 1, b + 2, b + 3});
      many.triangles.push_back({b + 2, b, b + 3});
    }
  }
  expectEdgebreakerRoundTrip(ctx, many);
}

TEST(Edgebreaker, NonOrientableAndNonManifold) {
  const TileContext ctx{12, {}};
  // A Moebius strip: no orientation agrees across every edge, so one edge is cut.
  QuantizedMesh mobius;
  const uint32_t n = 30;
  for (uint32_t i = 0; i < n; ++i)
    for (int s = -1; s <= 1; s += 2) {
      const double u = 6.283185307179586 * i / n, w = 80.0 * s;
      const double r = 500 + w * std::cos(u / 2);
      mobius.positions.push_back({uint32_t(2000 + r * std::cos(u)), uint32_t(2000 + r * std::sin(u)),
                                  uint32_t(2000 + w * std::sin(u / 2))});
    }
  for (uint32_t i = 0; i < n; ++i) {
    const uint32_t a = 2 * i, b = 2 * i + 1;
    // The strip's last quad joins the first with its sides swapped.
    const uint32_t c = i + 1 < n ? 2 * i + 2 : 1, d = i + 1 < n ? 2 * i + 3 : 0;
    mobius.triangles.push_back({a, c, b});
    mobius.triangles.push_back({b, c, d});
  }
  expectEdgebreakerRoundTrip(ctx, mobius);

  // Fins: extra triangles on edges of a closed sphere (three and four triangles on one edge). The cut leaves
  // two edges between the same pair of vertices.
  QuantizedMesh fin = *quantizeMesh(icosphere(2), *makeGrid(boundingBox(icosphere(2)), 12), {}, nullptr);
  for (int f = 0; f < 3; ++f) {
    const Triangle t = fin.triangles[size_t(17 * f)];
    const uint32_t tip = uint32_t(fin.positions.size());
    fin.positions.push_back({uint32_t(100 + f), 4000, 4000});
    fin.triangles.push_back({t[0], t[1], tip});
  }
  const Triangle t0 = fin.triangles[40];
  const uint32_t tip = uint32_t(fin.positions.size());
  fin.positions.push_back({4000, 100, 4000});
  fin.positions.push_back({4000, 200, 100});
  fin.triangles.push_back({t0[0], t0[1], tip});
  fin.triangles.push_back({t0[1], t0[0], tip + 1});
  expectEdgebreakerRoundTrip(ctx, fin);

  // Two cones touching at their apex; two tetrahedra sharing only an edge.
  QuantizedMesh cones;
  cones.positions.push_back({2000, 2000, 2000});
  for (int side = -1; side <= 1; side += 2)
    for (uint32_t i = 0; i < 12; ++i) {
      const double a = 6.283185307179586 * i / 12;
      cones.positions.push_back({uint32_t(2000 + 500 * std::cos(a)), uint32_t(2000 + 500 * std::sin(a)),
                                 uint32_t(2000 + 700 * side)});
    }
  for (uint32_t s = 0; s < 2; ++s)
    for (uint32_t i = 0; i < 12; ++i) cones.triangles.push_back({0, 1 + 12 * s + i, 1 + 12 * s + (i + 1) % 12});
  expectEdgebreakerRoundTrip(ctx, cones);
  QuantizedMesh tets;
  tets.positions = {{0, 0, 0}, {100, 0, 0}, {50, 90, 0}, {50, 30, 80}, {50, 30, 4000}};
  tets.triangles = {{0, 1, 2}, {0, 3, 1}, {1, 3, 2}, {2, 3, 0}, {0, 1, 4}, {1, 2, 4}, {2, 0, 4}};
  expectEdgebreakerRoundTrip(ctx, tets);
}

TEST(Edgebreaker, BoundariesAndHoles) {
  const TileContext ctx{12, {}};
  // A height field grid with square holes punched out.
  QuantizedMesh grid;
  const uint32_t n = 40;
  for (uint32_t i = 0; i < n; ++i)
    for (uint32_t j = 0; j < n; ++j)
      grid.positions.push_back({100 + 90 * i, 100 + 90 * j,
                                uint32_t(2000 + 300 * std::sin(0.3 * i) * std::cos(0.2 * j))});
  for (uint32_t i = 0; i + 1 < n; ++i)
    for (uint32_t j = 0; j + 1 < n; ++j) {
      if ((i / 5) % 2 == 1 && (j / 5) % 2 == 1 && i % 5 != 0 && j % 5 != 0) continue;
      const uint32_t a = i * n + j;
      grid.triangles.push_back({a, a + n, a + n + 1});
      grid.triangles.push_back({a, a + n + 1, a + 1});
    }
  expectEdgebreakerRoundTrip(ctx, grid);
}

// Payload header: varint points, varint triangles, varint cut-mesh faces, then the range-coded stream.
std::vector<uint8_t> header(uint64_t n, uint64_t t, uint64_t faces, size_t tail = 16) {
  std::vector<uint8_t> out;
  ByteWriter w(out);
  w.varint(n);
  w.varint(t);
  w.varint(faces);
  out.resize(out.size() + tail, 0x5A);
  return out;
}

TEST(Edgebreaker, HostileCountsAreRefusedBeforeDecoding) {
  const TileContext ctx{12, {}};
  const DecodeLimits lim{100, 100};
  // More than the index allows.
  EXPECT_EQ(codec().decode(ctx, codec().version, header(101, 10, 10), lim).status().code(), ErrorCode::kMalformed);
  EXPECT_EQ(codec().decode(ctx, codec().version, header(10, 1u << 31, 10), lim).status().code(), ErrorCode::kMalformed);
  EXPECT_EQ(codec().decode(ctx, codec().version, header(uint64_t(1) << 60, 1, 1), lim).status().code(),
            ErrorCode::kMalformed);
  // More cut faces than triangles and their boundary edges can make; faces without triangles; an empty tile
  // with bytes after it.
  EXPECT_EQ(codec().decode(ctx, codec().version, header(10, 10, 41), lim).status().code(), ErrorCode::kMalformed);
  EXPECT_EQ(codec().decode(ctx, codec().version, header(10, 0, 5), lim).status().code(), ErrorCode::kMalformed);
  EXPECT_EQ(codec().decode(ctx, codec().version, header(0, 0, 0, 1), lim).status().code(), ErrorCode::kMalformed);
  EXPECT_TRUE(codec().decode(ctx, codec().version, header(0, 0, 0, 0), lim).isOk());
  // Garbage after a plausible header: an error or a valid mesh within the limits, never more.
  std::mt19937 rng(5);
  for (int trial = 0; trial < 500; ++trial) {
    auto bytes = header(1 + rng() % 100, 1 + rng() % 100, 1 + rng() % 100, 1 + rng() % 64);
    for (size_t i = 3; i < bytes.size(); ++i) bytes[i] = uint8_t(rng());
    auto d = codec().decode(ctx, codec().version, bytes, lim);
    if (d.isOk()) {
      EXPECT_TRUE(validateTile(ctx, *d).isOk());
      EXPECT_LE(d->positions.size(), lim.vertices);
      EXPECT_LE(d->triangles.size(), lim.faces);
    }
  }
}

}  // namespace
}  // namespace scanpress
