// Per-vertex scalar channels (issue 22 part 1: a scanner's confidence, intensity or quality kept at its own type):
// the ordered-integer mapping against every special bit pattern, bit-exact round trips of every type through the
// codecs that carry them (store, kdtree, octree, edgebreaker) with and without normals and colors, twins that differ
// in their scalars alone, coarse levels showing a point of their cell, the container's v2 header (its channel table
// against hostile bytes, v1 still written without channels), and the lossy codecs refusing them by name.
#include <gtest/gtest.h>

#include <bit>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <limits>
#include <map>
#include <random>

#include "engine/codecs/attributes.h"
#include "engine/codecs/codec.h"
#include "engine/container/container.h"
#include "engine/io/crc32c.h"
#include "engine/quantize.h"
#include "engine/shapes.h"
#include "test_util.h"

namespace scanpress {
namespace {

using hierarchy::scalarFromOrdered;
using hierarchy::scalarOrdered;

const std::vector<ScalarChannel> kEveryType = {
    {"c_int8", ScalarType::kInt8},        {"quality", ScalarType::kUint8},    {"c_int16", ScalarType::kInt16},
    {"c_uint16", ScalarType::kUint16},    {"c_int32", ScalarType::kInt32},    {"flags", ScalarType::kUint32},
    {"confidence", ScalarType::kFloat32}, {"intensity", ScalarType::kFloat64}};

uint32_t floatBits(float f) { return std::bit_cast<uint32_t>(f); }
uint64_t doubleBits(double d) { return std::bit_cast<uint64_t>(d); }

// Special values of each type as bit patterns (float64: low word first): extremes, zeros of both signs, infinities,
// NaNs with payloads, the smallest subnormals.
std::vector<std::array<uint32_t, 2>> specials(ScalarType t) {
  std::vector<std::array<uint32_t, 2>> out;
  const auto add = [&](uint64_t b) { out.push_back({uint32_t(b), uint32_t(b >> 32)}); };
  switch (t) {
    case ScalarType::kFloat32:
      for (float f :
           {0.f, -0.f, 1.f, -1.f, std::numeric_limits<float>::infinity(), -std::numeric_limits<float>::infinity(),
            std::numeric_limits<float>::denorm_min(), -std::numeric_limits<float>::denorm_min(),
            std::numeric_limits<float>::max(), std::numeric_limits<float>::lowest()})
        add(floatBits(f));
      add(0x7FC00001u), add(0xFFFFFFFFu), add(0x7F800001u);  // NaNs with payloads
      break;
    case ScalarType::kFloat64:
      for (double d : {0.0, -0.0, 0.5, -2.0, std::numeric_limits<double>::infinity(),
                       -std::numeric_limits<double>::infinity(), std::numeric_limits<double>::denorm_min(),
                       std::numeric_limits<double>::max(), std::numeric_limits<double>::lowest()})
        add(doubleBits(d));
      add(0x7FF8000000000001ull), add(0xFFFFFFFFFFFFFFFFull);
      break;
    default: {
      const int bits = 8 * scalarTypeBytes(t);
      const uint64_t mask = bits == 32 ? 0xFFFFFFFFull : (uint64_t{1} << bits) - 1;
      for (uint64_t v : {uint64_t{0}, uint64_t{1}, mask, mask >> 1, (mask >> 1) + 1, mask - 1}) add(v);
    }
  }
  return out;
}

TEST(ScalarChannels, OrderedIntegersRoundTripEveryBitPatternInOrder) {
  std::mt19937_64 rng(22);
  for (const ScalarChannel& c : kEveryType) {
    SCOPED_TRACE(c.name);
    const int bits = 8 * scalarTypeBytes(c.type);
    std::vector<std::array<uint32_t, 2>> values = specials(c.type);
    for (int i = 0; i < 20000; ++i) {
      const uint64_t r = bits == 64 ? rng() : rng() & ((uint64_t{1} << bits) - 1);
      values.push_back({uint32_t(r), uint32_t(r >> 32)});
    }
    for (const auto& w : values) {
      const int64_t x = scalarOrdered(c.type, w.data());
      EXPECT_EQ(hierarchy::wrapOrdered(c.type, x), x) << "in the type's range";
      std::array<uint32_t, 2> back{0, 0};
      scalarFromOrdered(c.type, x, back.data());
      ASSERT_EQ(back[0], w[0]);
      if (c.type == ScalarType::kFloat64) {
        ASSERT_EQ(back[1], w[1]);
      }
    }
  }
  // Floats: the ordered integers follow the values (and -0 sits just below +0).
  std::vector<float> fs = {
      -std::numeric_limits<float>::infinity(), -3.5f, -1.f, -1e-30f, -0.f, 0.f, 1e-30f, 0.25f, 1.f, 7.f,
      std::numeric_limits<float>::max()};
  for (size_t i = 1; i < fs.size(); ++i) {
    const uint32_t a = floatBits(fs[i - 1]), b = floatBits(fs[i]);
    EXPECT_LT(scalarOrdered(ScalarType::kFloat32, &a), scalarOrdered(ScalarType::kFloat32, &b)) << fs[i];
  }
}

// A sphere with one channel of each type (smooth fields, noise in the low bits, and every special value), twins at
// one position that differ in their scalars alone (kept apart), and an isolated vertex.
QuantizedMesh scalarSphere(const AttributeLayout& layout, uint32_t seed, int levels = 4) {
  const Mesh sphere = icosphere(levels);
  const Grid grid = *makeGrid(boundingBox(sphere), 12);
  QuantizedMesh q = *quantizeMesh(sphere, grid, {}, nullptr);
  std::mt19937_64 rng(seed);
  const size_t stride = size_t(layout.scalarStride());
  const auto row = [&](const Vec3d& p, size_t i) {
    std::vector<uint32_t> r;
    for (const ScalarChannel& c : layout.scalars) {
      const auto sp = specials(c.type);
      std::array<uint32_t, 2> w{0, 0};
      if (i % 17 == 3) {
        w = sp[(i / 17) % sp.size()];
      } else {
        const double field = p[0] + 0.5 * p[1] * p[2];  // in [-1.5, 1.5]
        switch (c.type) {
          case ScalarType::kFloat32: w[0] = floatBits(float(0.5 + 0.3 * field) + float(rng() % 3) * 1e-7f); break;
          case ScalarType::kFloat64: {
            const uint64_t b = doubleBits(1000.0 * field + double(rng() % 1000) * 1e-9);
            w = {uint32_t(b), uint32_t(b >> 32)};
            break;
          }
          default: {
            const int bits = 8 * scalarTypeBytes(c.type);
            const bool is_signed = c.type == ScalarType::kInt8 || c.type == ScalarType::kInt16 ||
                                   c.type == ScalarType::kInt32;
            const double scale = std::ldexp(1.0, bits - 3);
            const int64_t v = int64_t(std::llround(field * scale)) + int64_t(rng() % 3) +
                              (is_signed ? 0 : int64_t(2 * scale));
            w[0] = uint32_t(uint64_t(v) & (bits == 32 ? 0xFFFFFFFFull : (uint64_t{1} << bits) - 1));
          }
        }
      }
      r.push_back(w[0]);
      if (c.type == ScalarType::kFloat64) r.push_back(w[1]);
    }
    return r;
  };
  for (size_t i = 0; i < q.positions.size(); ++i) {
    const auto r = row(sphere.positions[i], i);
    q.scalars.insert(q.scalars.end(), r.begin(), r.end());
    if (layout.hasNormals())
      q.normals.push_back(encodeOctahedral(Vec3f{float(sphere.positions[i][0]), float(sphere.positions[i][1]),
                                                 float(sphere.positions[i][2])},
                                           layout.normal_bits));
    if (layout.hasColors()) q.colors.push_back({uint8_t(i), uint8_t(i * 7), 90, 255});
  }
  for (int k = 0; k < 12; ++k) {  // twins: same position, normal and color, other scalars, in a triangle
    const uint32_t twin = uint32_t(q.positions.size());
    const auto t = q.triangles[size_t(k) * 41 % q.triangles.size()];
    q.positions.push_back(q.positions[t[0]]);
    if (layout.hasNormals()) q.normals.push_back(q.normals[t[0]]);
    if (layout.hasColors()) q.colors.push_back(q.colors[t[0]]);
    for (size_t w = 0; w < stride; ++w) q.scalars.push_back(q.scalars[t[0] * stride + w] ^ (1u << (k % 8)));
    q.triangles.push_back({twin, t[2], t[1]});
  }
  q.positions.push_back({2048, 2048, 2048});  // isolated
  if (layout.hasNormals()) q.normals.push_back({3, 3});
  if (layout.hasColors()) q.colors.push_back({1, 2, 3, 255});
  for (size_t w = 0; w < stride; ++w) q.scalars.push_back(uint32_t(0xA5A5A5A5u >> (w % 8)));
  // Each value masked to its type's width (the smooth integer fields above may carry high bits).
  for (size_t v = 0; v < q.positions.size(); ++v) {
    size_t o = 0;
    for (const ScalarChannel& c : layout.scalars) {
      if (scalarTypeBytes(c.type) < 4) q.scalars[v * stride + o] &= (1u << (8 * scalarTypeBytes(c.type))) - 1;
      o += size_t(scalarTypeWords(c.type));
    }
  }
  return q;
}

using Row = std::tuple<Vec3u, OctNormal, Rgba8, std::vector<uint32_t>>;
std::vector<Row> vertexRows(const QuantizedMesh& m, size_t stride) {
  std::vector<Row> out;
  for (size_t i = 0; i < m.positions.size(); ++i)
    out.emplace_back(m.positions[i], m.normals.empty() ? OctNormal{0, 0} : m.normals[i],
                     m.colors.empty() ? Rgba8{0, 0, 0, 0} : m.colors[i],
                     std::vector<uint32_t>(m.scalars.begin() + i * stride, m.scalars.begin() + (i + 1) * stride));
  std::sort(out.begin(), out.end());
  out.erase(std::unique(out.begin(), out.end()), out.end());
  return out;
}

class ScalarRoundTrip : public ::testing::TestWithParam<CodecId> {
 protected:
  const CodecInfo& codec() const { return *findCodec(GetParam()); }
};

std::vector<AttributeLayout> scalarLayouts() {
  AttributeLayout every;
  every.scalars = kEveryType;
  AttributeLayout with_attributes = every;
  with_attributes.normal_bits = 10, with_attributes.color_channels = 4;
  AttributeLayout one;
  one.scalars = {{"confidence", ScalarType::kFloat32}};
  return {every, with_attributes, one};
}

TEST_P(ScalarRoundTrip, EveryTypeIsBitExact) {
  for (const AttributeLayout& layout : scalarLayouts()) {
    SCOPED_TRACE(std::to_string(layout.scalars.size()) + " channels, normals " + std::to_string(layout.normal_bits));
    const QuantizedMesh q = scalarSphere(layout, 5);
    const TileContext ctx{12, layout};
    auto enc = encodeMesh(codec(), ctx, q);
    ASSERT_TRUE(enc.isOk()) << enc.status().toString();
    auto d = codec().decode(ctx, codec().version, enc->payload, limitsOf(enc->decoded));
    ASSERT_TRUE(d.isOk()) << d.status().toString();
    ASSERT_EQ(d->scalars.size(), d->positions.size() * size_t(layout.scalarStride()));
    const auto got = vertexRows(*d, size_t(layout.scalarStride())), want = vertexRows(q, size_t(layout.scalarStride()));
    ASSERT_EQ(got.size(), want.size()) << "twins differing in their scalars alone stay apart";
    EXPECT_TRUE(got == want);
  }
}

// The same tile with and without a smooth float channel: the prediction makes it cost less than its raw 32 bits.
TEST_P(ScalarRoundTrip, PredictionPredicts) {
  if (GetParam() == CodecId::kStore) GTEST_SKIP() << "store keeps values raw";
  AttributeLayout none, one;
  one.scalars = {{"c", ScalarType::kFloat32}, {"q", ScalarType::kUint8}};
  const Mesh sphere = icosphere(5);
  const Grid grid = *makeGrid(boundingBox(sphere), 12);
  QuantizedMesh q = *quantizeMesh(sphere, grid, {}, nullptr);
  auto plain = encodeMesh(codec(), TileContext{12, none}, q);
  ASSERT_TRUE(plain.isOk());
  for (size_t i = 0; i < q.positions.size(); ++i) {
    const Vec3d& p = sphere.positions[i];
    q.scalars.push_back(floatBits(float(std::round((0.5 + 0.4 * p[0] * p[1]) * 1e4) / 1e4)));
    q.scalars.push_back(uint32_t(std::lround(100 + 60 * p[2])));
  }
  auto with = encodeMesh(codec(), TileContext{12, one}, q);
  ASSERT_TRUE(with.isOk()) << with.status().toString();
  const double bits = 8.0 * double(with->payload.size() - plain->payload.size()) / double(q.positions.size());
  std::printf("%s: a smooth float and a smooth uchar cost %.2f bits per vertex (raw 40)\n", codec().name.data(), bits);
  EXPECT_LT(bits, 28.0);
  auto d = codec().decode(TileContext{12, one}, codec().version, with->payload, limitsOf(with->decoded));
  ASSERT_TRUE(d.isOk());
  EXPECT_TRUE(vertexRows(*d, 2) == vertexRows(q, 2));
}

// kdtree and octree (v3): every vertex of a coarse level shows the scalars of a point of the tile in its cell at the
// last level whose births are coded (as its normal and color), every level of the right size.
TEST_P(ScalarRoundTrip, CoarseLevelsShowAPointOfTheirCell) {
  if (!codec().progressive()) GTEST_SKIP() << codec().name << " is single-rate";
  AttributeLayout layout;
  layout.scalars = kEveryType;
  const QuantizedMesh q = scalarSphere(layout, 9);
  const size_t stride = size_t(layout.scalarStride());
  const TileContext ctx{12, layout};
  auto enc = encodeMesh(codec(), ctx, q);
  ASSERT_TRUE(enc.isOk()) << enc.status().toString();
  auto levels = codec().levels(ctx, codec().version, enc->payload, limitsOf(enc->decoded));
  ASSERT_TRUE(levels.isOk());
  const uint32_t limit = std::max<uint32_t>(64, uint32_t(q.positions.size()) / 16);
  int last_coded = -1;
  size_t checked = 0;
  for (size_t i = 0; i < levels->size(); ++i) {
    const CodecLevel& l = (*levels)[i];
    auto d = codec().decode_level(ctx, codec().version, std::span(enc->payload.data(), l.end_bytes), l.level,
                                  limitsOf(enc->decoded));
    ASSERT_TRUE(d.isOk()) << "level " << l.level << ": " << d.status().toString();
    ASSERT_EQ(d->scalars.size(), d->positions.size() * stride) << "level " << l.level;
    if (i == 0 || l.complete) continue;  // the root derives its attributes; the last level is the tile
    if (d->positions.size() <= limit) last_coded = int(l.level);
    ASSERT_GE(last_coded, 0);
    const int shift = 12 - last_coded;
    std::map<Vec3u, std::vector<std::vector<uint32_t>>> in_cell;
    for (size_t v = 0; v < q.positions.size(); ++v)
      in_cell[{q.positions[v][0] >> shift, q.positions[v][1] >> shift, q.positions[v][2] >> shift}]
          .push_back(std::vector<uint32_t>(q.scalars.begin() + v * stride, q.scalars.begin() + (v + 1) * stride));
    size_t bad = 0;
    for (size_t v = 0; v < d->positions.size(); ++v) {
      const Vec3u& p = d->positions[v];
      const auto it = in_cell.find({p[0] >> shift, p[1] >> shift, p[2] >> shift});
      const std::vector<uint32_t> shown(d->scalars.begin() + v * stride, d->scalars.begin() + (v + 1) * stride);
      bad += it == in_cell.end() || std::find(it->second.begin(), it->second.end(), shown) == it->second.end();
    }
    EXPECT_EQ(bad, 0u) << "level " << l.level << ": vertices showing no point of their cell at level " << last_coded;
    checked += d->positions.size();
  }
  EXPECT_GT(checked, 500u);
}

TEST_P(ScalarRoundTrip, TruncationsAndCorruptionsFailCleanly) {
  AttributeLayout layout;
  layout.scalars = kEveryType;
  layout.normal_bits = 8;
  const QuantizedMesh q = scalarSphere(layout, 3);
  const TileContext ctx{12, layout};
  auto enc = encodeMesh(codec(), ctx, q);
  ASSERT_TRUE(enc.isOk()) << enc.status().toString();
  const auto& bytes = enc->payload;
  // Cuts through the whole payload, every byte of the last ones (the attributes are coded last). Fewer under ASan.
#if defined(__SANITIZE_ADDRESS__)
  constexpr size_t kTail = 16, kStride = 389;
  constexpr int kFlips = 40;
#else
  constexpr size_t kTail = 64, kStride = 97;
  constexpr int kFlips = 150;
#endif
  for (size_t n = 0; n < bytes.size(); n += (n + kTail >= bytes.size() ? 1 : kStride)) {
    auto d = codec().decode(ctx, codec().version, std::span<const uint8_t>(bytes.data(), n), limitsOf(enc->decoded));
    EXPECT_FALSE(d.isOk()) << "cut to " << n << " of " << bytes.size() << " bytes decoded";
  }
  std::mt19937 rng(1);
  for (int i = 0; i < kFlips; ++i) {
    std::vector<uint8_t> bad = bytes;
    bad[rng() % bad.size()] ^= uint8_t(1u << (rng() % 8));
    auto d = codec().decode(ctx, codec().version, bad, limitsOf(enc->decoded));
    if (d.isOk()) {
      EXPECT_EQ(d->scalars.size(), d->positions.size() * size_t(layout.scalarStride()));
    }
  }
}

std::vector<CodecId> scalarCodecs() {
  return {CodecId::kStore, CodecId::kKdtree, CodecId::kOctree, CodecId::kEdgebreaker};
}

INSTANTIATE_TEST_SUITE_P(Codecs, ScalarRoundTrip, ::testing::ValuesIn(scalarCodecs()),
                         [](const ::testing::TestParamInfo<CodecId>& info) {
  return std::string(findCodec(info.param)->name);
});

TEST(ScalarChannels, LossyCodecsRefuseThemByName) {
  AttributeLayout layout;
  layout.scalars = {{"confidence", ScalarType::kFloat32}};
  const QuantizedMesh q = scalarSphere(layout, 1);
  for (CodecId id : {CodecId::kPm, CodecId::kPrm}) {
    auto enc = encodeMesh(*findCodec(id), TileContext{12, layout}, q);
    ASSERT_FALSE(enc.isOk());
    EXPECT_EQ(enc.status().code(), ErrorCode::kInvalidArgument);
    EXPECT_NE(enc.status().message().find("scalar channels"), std::string::npos) << enc.status().toString();
  }
}

// The container: v2 with a channel table when the layout has scalars (read back exactly), v1 byte for byte as
// before without them.
TEST(ScalarChannels, ContainerWritesVersion2OnlyWithChannels) {
  AttributeLayout layout;
  layout.scalars = kEveryType;
  const QuantizedMesh q = scalarSphere(layout, 2);
  const Grid grid{{0, 0, 0}, 1.0, 12};
  const std::vector<QuantizedMesh> tiles = {q, q};
  auto file = encodeContainer(grid, layout, *findCodec(CodecId::kKdtree), tiles);
  ASSERT_TRUE(file.isOk()) << file.status().toString();
  auto pc = parseContainer(*file, "mem");
  ASSERT_TRUE(pc.isOk()) << pc.status().toString();
  EXPECT_EQ(pc->header.version, 2u);
  EXPECT_EQ(pc->header.layout, layout);
  EXPECT_EQ(
      pc->header.header_size, kHeaderSize + 1 + 4 + [&] {
        size_t n = 0;
        for (const auto& c : layout.scalars) n += 2 + c.name.size();
        return n;
      }());
  for (const TileEntry& e : pc->tiles) {
    auto payload = parseTileChunk(std::span(*file).subspan(e.offset, e.chunk_bytes), e, "mem");
    ASSERT_TRUE(payload.isOk());
    auto d = decodeTilePayload(pc->header, e, *payload, "mem");
    ASSERT_TRUE(d.isOk()) << d.status().toString();
    EXPECT_TRUE(vertexRows(*d, size_t(layout.scalarStride())) == vertexRows(q, size_t(layout.scalarStride())));
  }
  QuantizedMesh plain = q;
  plain.scalars.clear();
  auto v1 = encodeContainer(grid, AttributeLayout{}, *findCodec(CodecId::kKdtree), std::vector<QuantizedMesh>{plain});
  ASSERT_TRUE(v1.isOk());
  uint32_t version = 0;
  std::memcpy(&version, v1->data() + 8, 4);
  EXPECT_EQ(version, 1u);
  // Names the writer refuses: empty, with a space, twice.
  for (const std::vector<ScalarChannel>& bad :
       {std::vector<ScalarChannel>{{"", ScalarType::kUint8}}, std::vector<ScalarChannel>{{"a b", ScalarType::kUint8}},
        std::vector<ScalarChannel>{{"a", ScalarType::kUint8}, {"a", ScalarType::kInt8}}}) {
    AttributeLayout l;
    l.scalars = bad;
    QuantizedMesh m = plain;
    m.scalars.assign(m.positions.size() * bad.size(), 0);
    auto r = encodeContainer(grid, l, *findCodec(CodecId::kStore), std::vector<QuantizedMesh>{m});
    EXPECT_FALSE(r.isOk());
  }
}

// Hostile channel tables, checksums repaired so that the parser itself must refuse them: every byte of the table
// and the header size set to every value near the truth; no crash, no acceptance of a table that does not parse.
TEST(ScalarChannels, HostileChannelTablesFailCleanly) {
  AttributeLayout layout;
  layout.scalars = {{"confidence", ScalarType::kFloat32}, {"intensity", ScalarType::kUint16}};
  const QuantizedMesh q = scalarSphere(layout, 4);
  auto file =
      encodeContainer(Grid{{0, 0, 0}, 1.0, 12}, layout, *findCodec(CodecId::kStore), std::vector<QuantizedMesh>{q});
  ASSERT_TRUE(file.isOk());
  auto pc = parseContainer(*file, "mem");
  ASSERT_TRUE(pc.isOk());
  const size_t hs = pc->header.header_size;
  const auto repair = [&](std::vector<uint8_t>& b, uint32_t size) {
    const uint32_t crc_fixed = crc32c(std::span(b).first(kHeaderSize - 4));
    std::memcpy(b.data() + kHeaderSize - 4, &crc_fixed, 4);
    if (size >= kHeaderSize + 4 && size <= b.size()) {
      const uint32_t crc = crc32c(std::span(b).subspan(kHeaderSize, size - kHeaderSize - 4));
      std::memcpy(b.data() + size - 4, &crc, 4);
    }
  };
  size_t refused = 0, tried = 0;
  for (size_t at = kHeaderSize; at + 4 < hs; ++at)
    for (const int v : std::vector<int>{0, 1, 8, 9, 32, 255, int((*file)[at]) + 1, int((*file)[at]) - 1}) {
      std::vector<uint8_t> b = *file;
      b[at] = uint8_t(v);
      repair(b, uint32_t(hs));
      auto r = parseContainer(b, "mem");
      ++tried;
      if (!r.isOk()) {
        ++refused;
        EXPECT_NE(r.status().message().find("mem"), std::string::npos);
        continue;
      }
      // Accepted: a valid table (a renamed channel or a changed type): every tile still decodes or fails cleanly.
      for (const TileEntry& e : r->tiles) {
        auto payload = parseTileChunk(std::span(b).subspan(e.offset, e.chunk_bytes), e, "mem");
        if (payload.isOk()) {
          (void)decodeTilePayload(r->header, e, *payload, "mem");
        }
      }
    }
  for (uint32_t size : {uint32_t(kHeaderSize), uint32_t(kHeaderSize + 6), uint32_t(hs - 1), uint32_t(hs + 1),
                        uint32_t(kMaxHeaderSize + 1), 0xFFFFFFFFu}) {
    std::vector<uint8_t> b = *file;
    std::memcpy(b.data() + 12, &size, 4);
    repair(b, size);
    EXPECT_FALSE(parseContainer(b, "mem").isOk()) << "header size " << size;
  }
  EXPECT_GT(refused, tried / 4);
  // An index that starts inside the header's channel table (its footer's checksum repaired) is refused.
  {
    std::vector<uint8_t> b = *file;
    const size_t footer = b.size() - kFooterSize;
    const uint64_t index_offset = kHeaderSize + 4, index_bytes = footer - index_offset;
    std::memcpy(b.data() + footer, &index_offset, 8);
    std::memcpy(b.data() + footer + 8, &index_bytes, 8);
    const uint32_t crc = crc32c(std::span(b).subspan(footer, 20));
    std::memcpy(b.data() + footer + 20, &crc, 4);
    auto r = parseContainer(b, "mem");
    ASSERT_FALSE(r.isOk());
    EXPECT_NE(r.status().message().find("inside the header"), std::string::npos) << r.status().toString();
  }
  // The footer's version must be the header's.
  std::vector<uint8_t> b = *file;
  const size_t footer = b.size() - kFooterSize;
  const uint32_t one = 1;
  std::memcpy(b.data() + footer + 16, &one, 4);
  const uint32_t crc = crc32c(std::span(b).subspan(footer, 20));
  std::memcpy(b.data() + footer + 20, &crc, 4);
  auto r = parseContainer(b, "mem");
  ASSERT_FALSE(r.isOk());
  EXPECT_NE(r.status().message().find("version"), std::string::npos) << r.status().toString();
}

// Golden containers of version 2 (tests/golden/scalars-<codec>.spz, kept forever): each build decodes them to the
// sphere they were made from, and the writer must still produce them byte for byte (the scalar channels' coding
// is part of the format). SCANPRESS_WRITE_GOLDEN=1 writes the missing ones.
TEST(ScalarChannels, GoldenContainersDecodeAndAreReproduced) {
  AttributeLayout layout;
  layout.scalars = kEveryType;
  layout.normal_bits = 10, layout.color_channels = 4;
  const QuantizedMesh q = scalarSphere(layout, 11, 2);
  const Grid grid{{0, 0, 0}, 1.0, 12};
  for (CodecId id : scalarCodecs()) {
    const CodecInfo& codec = *findCodec(id);
    SCOPED_TRACE(codec.name);
    const std::string path = std::string(SCANPRESS_GOLDEN) + "/scalars-" + std::string(codec.name) + ".spz";
    auto bytes = encodeContainer(grid, layout, codec, std::vector<QuantizedMesh>{q});
    ASSERT_TRUE(bytes.isOk()) << bytes.status().toString();
    if (!std::filesystem::exists(path) && std::getenv("SCANPRESS_WRITE_GOLDEN")) {
      testing::writeBytes(path, std::string(bytes->begin(), bytes->end()));
    }
    const std::vector<uint8_t> golden = testing::readBytes(path);
    ASSERT_FALSE(golden.empty()) << path << " missing (SCANPRESS_WRITE_GOLDEN=1 writes it)";
    EXPECT_TRUE(golden == *bytes) << "the writer no longer reproduces " << path;
    auto pc = parseContainer(golden, path);
    ASSERT_TRUE(pc.isOk()) << pc.status().toString();
    ASSERT_EQ(pc->tiles.size(), 1u);
    const TileEntry& e = pc->tiles[0];
    auto payload = parseTileChunk(std::span(golden).subspan(e.offset, e.chunk_bytes), e, path);
    ASSERT_TRUE(payload.isOk());
    auto d = decodeTilePayload(pc->header, e, *payload, path);
    ASSERT_TRUE(d.isOk()) << d.status().toString();
    EXPECT_TRUE(vertexRows(*d, size_t(layout.scalarStride())) == vertexRows(q, size_t(layout.scalarStride())));
  }
}

}  // namespace
}  // namespace scanpress
