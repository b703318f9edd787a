// Per-vertex scalar channels (issue 22 part 1: a scanner's confidence, intensity or quality kept at its own type):
// the ordered-integer mapping against every special bit pattern, bit-exact round trips of every type through the
// codecs that carry them (store, kdtree, octree, edgebreaker) with and without normals and colors, twins that differ
// in their scalars alone, coarse levels showing a point of their cell, the container's v2 header (its channel table
// against hostile bytes, v1 still written without channels), and the lossy codecs refusing them by name; then
// quantized channels and texture coordinates (namespace uv below).
#include <gtest/gtest.h>

#include <bit>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <limits>
#include <map>
#include <random>
#include <set>

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
    auto d = codec().decode(ctx, payloadVersion(codec(), *enc), enc->payload, limitsOf(enc->decoded));
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
  auto d = codec().decode(TileContext{12, one}, payloadVersion(codec(), *with), with->payload, limitsOf(with->decoded));
  ASSERT_TRUE(d.isOk());
  EXPECT_TRUE(vertexRows(*d, 2) == vertexRows(q, 2));
}

// kdtree and octree (v3): every vertex of a coarse level shows the scalars of a point of the tile in its cell at the
// last level whose births are coded (as its normal and color), every level of the right size; kdtree v4: of a point
// of the tile.
TEST_P(ScalarRoundTrip, CoarseLevelsShowAPointOfTheirCell) {
  if (!codec().progressive()) GTEST_SKIP() << codec().name << " is single-rate";
  AttributeLayout layout;
  layout.scalars = kEveryType;
  const QuantizedMesh q = scalarSphere(layout, 9);
  const size_t stride = size_t(layout.scalarStride());
  const TileContext ctx{12, layout};
  auto enc = encodeMesh(codec(), ctx, q);
  ASSERT_TRUE(enc.isOk()) << enc.status().toString();
  auto levels = codec().levels(ctx, payloadVersion(codec(), *enc), enc->payload, limitsOf(enc->decoded));
  ASSERT_TRUE(levels.isOk());
  const uint32_t limit = std::max<uint32_t>(64, uint32_t(q.positions.size()) / 16);
  int last_coded = -1;
  size_t checked = 0;
  for (size_t i = 0; i < levels->size(); ++i) {
    const CodecLevel& l = (*levels)[i];
    auto d = codec().decode_level(ctx, payloadVersion(codec(), *enc), std::span(enc->payload.data(), l.end_bytes),
                                  l.level, limitsOf(enc->decoded));
    ASSERT_TRUE(d.isOk()) << "level " << l.level << ": " << d.status().toString();
    ASSERT_EQ(d->scalars.size(), d->positions.size() * stride) << "level " << l.level;
    if (i == 0 || l.complete) continue;  // the root derives its attributes; the last level is the tile
    if (d->positions.size() <= limit) last_coded = int(l.level);
    ASSERT_GE(last_coded, 0);
    // kdtree v4 (the icosphere's vertices along its base edges are wedges here: their scalars differ): a vertex by
    // a seam may show a value chosen among its ancestors' (creases.h), a point of the tile's.
    const int shift = payloadVersion(codec(), *enc) >= 4 ? 12 : 12 - last_coded;
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
    auto d = codec().decode(ctx, payloadVersion(codec(), *enc), std::span<const uint8_t>(bytes.data(), n),
                            limitsOf(enc->decoded));
    EXPECT_FALSE(d.isOk()) << "cut to " << n << " of " << bytes.size() << " bytes decoded";
  }
  std::mt19937 rng(1);
  for (int i = 0; i < kFlips; ++i) {
    std::vector<uint8_t> bad = bytes;
    bad[rng() % bad.size()] ^= uint8_t(1u << (rng() % 8));
    auto d = codec().decode(ctx, payloadVersion(codec(), *enc), bad, limitsOf(enc->decoded));
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

// Every byte of `file`'s header table (after the fixed header, before the table's checksum) set to each of `values`
// and to its own value plus and minus one, the table's checksum repaired so that the parser itself must refuse what
// does not parse. Every refusal names the file; `accepted` sees each header that parses, whose tiles then decode
// or fail cleanly. Returns (refused, tried).
template <class Accepted>
std::pair<size_t, size_t> mutateHeaderTable(const std::vector<uint8_t>& file, const std::vector<int>& values,
                                            const Accepted& accepted) {
  const auto pc = parseContainer(file, "mem");
  EXPECT_TRUE(pc.isOk());
  if (!pc.isOk()) return {0, 0};
  const size_t hs = pc->header.header_size;
  size_t refused = 0, tried = 0;
  for (size_t at = kHeaderSize; at + 4 < hs; ++at) {
    for (const int v : values) {
      std::vector<uint8_t> b = file;
      b[at] = uint8_t(v == 256 ? file[at] + 1 : v == -1 ? file[at] - 1 : v);
      const uint32_t crc = crc32c(std::span(b).subspan(kHeaderSize, hs - kHeaderSize - 4));
      std::memcpy(b.data() + hs - 4, &crc, 4);
      auto r = parseContainer(b, "mem");
      ++tried;
      if (!r.isOk()) {
        ++refused;
        EXPECT_NE(r.status().message().find("mem"), std::string::npos);
        continue;
      }
      accepted(r->header);
      for (const TileEntry& e : r->tiles) {
        auto payload = parseTileChunk(std::span(b).subspan(e.offset, e.chunk_bytes), e, "mem");
        if (payload.isOk()) (void)decodeTilePayload(r->header, e, *payload, "mem");
      }
    }
  }
  return {refused, tried};
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
  // Accepted: a valid table (a renamed channel or a changed type), whose tiles decode or fail cleanly.
  const auto [refused, tried] = mutateHeaderTable(*file, {0, 1, 8, 9, 32, 255, 256, -1}, [](const ContainerHeader&) {});
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
// is part of the format). SCANPRESS_WRITE_GOLDEN=1 writes the missing ones. pm v4 welded the sphere's twins: it
// decodes to the first vertex's row at each position (v5 keeps them); prm (v2) to what it coded.
TEST(ScalarChannels, GoldenContainersDecodeAndAreReproduced) {
  AttributeLayout layout;
  layout.scalars = kEveryType;
  layout.normal_bits = 10, layout.color_channels = 4;
  const QuantizedMesh q = scalarSphere(layout, 11, 2);
  const Grid grid{{0, 0, 0}, 1.0, 12};
  std::vector<CodecId> codecs = scalarCodecs();
  codecs.push_back(CodecId::kPm);
  codecs.push_back(CodecId::kPrm);
  QuantizedMesh welded;  // the first vertex at each position, as pm keeps it
  {
    const size_t stride = size_t(layout.scalarStride());
    std::set<Vec3u> seen;
    for (size_t v = 0; v < q.positions.size(); ++v)
      if (seen.insert(q.positions[v]).second) {
        welded.positions.push_back(q.positions[v]);
        welded.normals.push_back(q.normals[v]);
        welded.colors.push_back(q.colors[v]);
        welded.scalars.insert(welded.scalars.end(), q.scalars.begin() + ptrdiff_t(v * stride),
                              q.scalars.begin() + ptrdiff_t((v + 1) * stride));
      }
    ASSERT_LT(welded.positions.size(), q.positions.size()) << "the sphere has twins";
  }
  for (CodecId id : codecs) {
    const CodecInfo& codec = *findCodec(id);
    SCOPED_TRACE(codec.name);
    // The container the writer makes now. Kdtree writes version 5 and octree version 4 for the sphere (its twins'
    // scalars differ: cut edges) since creases went through their coarse levels (kdtree v4 coded it as v3); their
    // version 3 containers stay, decoded below.
    const std::string prefix = std::string(SCANPRESS_GOLDEN) + "/scalars-" + std::string(codec.name);
    // pm writes version 5 (wedges: the twins kept) since it keeps creases and seams; its version 4 container stays.
    const bool creased = id == CodecId::kKdtree || id == CodecId::kOctree;
    const bool versioned = creased || id == CodecId::kPm;
    const std::string path = versioned ? prefix + "-v" + std::to_string(codec.version) + ".spz" : prefix + ".spz";
    auto bytes = encodeContainer(grid, layout, codec, std::vector<QuantizedMesh>{q});
    ASSERT_TRUE(bytes.isOk()) << bytes.status().toString();
    if (!std::filesystem::exists(path) && std::getenv("SCANPRESS_WRITE_GOLDEN")) {
      testing::writeBytes(path, std::string(bytes->begin(), bytes->end()));
    }
    const std::vector<uint8_t> golden = testing::readBytes(path);
    ASSERT_FALSE(golden.empty()) << path << " missing (SCANPRESS_WRITE_GOLDEN=1 writes it)";
    EXPECT_TRUE(golden == *bytes) << "the writer no longer reproduces " << path;
    std::vector<std::string> paths{path};
    if (versioned) paths.push_back(prefix + ".spz");
    for (const std::string& kept : paths) {
      SCOPED_TRACE(kept);
      const std::vector<uint8_t> container = testing::readBytes(kept);
      ASSERT_FALSE(container.empty()) << kept << " missing: golden containers are kept forever";
      auto pc = parseContainer(container, kept);
      ASSERT_TRUE(pc.isOk()) << pc.status().toString();
      ASSERT_EQ(pc->tiles.size(), 1u);
      const TileEntry& e = pc->tiles[0];
      auto payload = parseTileChunk(std::span(container).subspan(e.offset, e.chunk_bytes), e, kept);
      ASSERT_TRUE(payload.isOk());
      auto d = decodeTilePayload(pc->header, e, *payload, kept);
      ASSERT_TRUE(d.isOk()) << d.status().toString();
      if (id == CodecId::kPrm) {
        // This small noisy sphere codes smaller as it is than remeshed (prm keeps the smaller), so it decodes to
        // itself; the resampling is Prm.ScalarChannelsAreResampledAndDecodeExactly's subject.
        EXPECT_EQ(e.codec_version, 2);
        EXPECT_TRUE(vertexRows(*d, size_t(layout.scalarStride())) == vertexRows(q, size_t(layout.scalarStride())));
        continue;
      }
      const bool pm_welds = id == CodecId::kPm && kept != path;  // v4
      EXPECT_TRUE(vertexRows(*d, size_t(layout.scalarStride())) ==
                  vertexRows(pm_welds ? welded : q, size_t(layout.scalarStride())));
      if (id == CodecId::kPm) {
        EXPECT_EQ(e.codec_version, kept == path ? 5 : 4);
      }
      if (creased) {
        EXPECT_EQ(e.codec_version, kept == path ? codec.version : 3);
      }
    }
  }
}

// Quantized texture coordinates (issue 22 part 3, `--uv-bits`): a float channel with ScalarChannel::bits keeps
// multiples of 2^-bits and codecs code the multiple. Checked here: snapScalar against direct rounding and its
// refusals; bit-exact round trips of the levels through every codec that carries scalars, float32 and float64, at
// 1 to 24 bits, beside a lossless channel; encoders refusing values off their levels; the texture-space prediction
// on an irregular, anisotropic, partly mirrored chart; the container's version 3 header (channel bits and material
// names) against hostile bytes; and golden version 3 containers.
namespace uv {

TEST(UvBits, SnapScalarIsRoundingToMultiplesOfItsStep) {
  std::mt19937_64 rng(7);
  for (ScalarType type : {ScalarType::kFloat32, ScalarType::kFloat64})
    for (int bits : {1, 5, 12, 16, 24}) {
      const ScalarChannel c{"u", type, uint8_t(bits)};
      const double step = std::ldexp(1.0, -bits), limit = std::ldexp(1.0, 31 - bits);
      // The words of x at the channel's type.
      const auto store = [&](double x, uint32_t(&w)[2]) {
        if (type == ScalarType::kFloat32) {
          w[0] = floatBits(float(x));
        } else {
          const uint64_t b = std::bit_cast<uint64_t>(x);
          w[0] = uint32_t(b), w[1] = uint32_t(b >> 32);
        }
      };
      for (int i = 0; i < 20000; ++i) {
        // Values of every magnitude up to the limit, of both signs.
        const double magnitude = std::ldexp(double(rng() % 1000000) / 1e6, int(rng() % 40) - 10);
        const double x = (rng() & 1 ? -1 : 1) * std::min(magnitude, limit * 0.999);
        uint32_t w[2] = {0, 0};
        store(x, w);
        const double value = type == ScalarType::kFloat32 ? double(std::bit_cast<float>(w[0])) : x;
        ASSERT_TRUE(snapScalar(c, w)) << value << " at " << bits << " bits";
        const double snapped = type == ScalarType::kFloat32
                                   ? double(std::bit_cast<float>(w[0]))
                                   : std::bit_cast<double>(uint64_t(w[0]) | uint64_t(w[1]) << 32);
        // Within half a step of the value, or (float32 beyond 2^24 steps) within float32's own rounding.
        const double tolerance =
            std::max(step / 2, type == ScalarType::kFloat32 ? std::fabs(value) * std::ldexp(1.0, -23) : 0.0);
        ASSERT_LE(std::fabs(snapped - value), tolerance * (1 + 1e-12)) << value << " at " << bits << " bits";
        ASSERT_TRUE(onScalarLevel(c, w));
        uint32_t back[2] = {0, 0};
        scalarOfLevel(c, scalarLevel(c, w), back);
        ASSERT_EQ(back[0], w[0]);
        if (type == ScalarType::kFloat64) {
          ASSERT_EQ(back[1], w[1]);
        }
      }
      // Refused: beyond the levels' range, infinities, NaN; the value is left as it was.
      for (double bad : {limit * 1.01, -limit * 1.01, std::numeric_limits<double>::infinity(),
                         std::numeric_limits<double>::quiet_NaN()}) {
        uint32_t w[2] = {0, 0};
        store(bad, w);
        const uint32_t before = w[0];
        EXPECT_FALSE(snapScalar(c, w)) << bad;
        EXPECT_EQ(w[0], before);
        EXPECT_FALSE(onScalarLevel(c, w));
      }
    }
  // A level's value is one: 3 * 2^-12, and -0 snaps to +0.
  const ScalarChannel c{"u", ScalarType::kFloat32, 12};
  uint32_t w[1] = {floatBits(3.0f / 4096)};
  EXPECT_TRUE(onScalarLevel(c, w));
  EXPECT_EQ(scalarLevel(c, w), 3);
  w[0] = floatBits(-0.0f);
  EXPECT_FALSE(onScalarLevel(c, w));
  ASSERT_TRUE(snapScalar(c, w));
  EXPECT_EQ(w[0], floatBits(0.0f));
}

// An irregular chart: a jittered n x n grid on a gently curved sheet, each quad split along a random diagonal,
// with texture coordinates an anisotropic affine map of the position (not a similarity), mirrored (u negated) on
// the half x > 0.5 when `mirror`; and a float channel `c` beside them. Values snapped at `bits` (all channels
// float32 unless `f64`: u and v float64).
QuantizedMesh chart(int n, int bits, bool mirror, bool f64, AttributeLayout& layout, uint32_t seed = 3) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> jitter(-0.3, 0.3);
  const ScalarType uv_type = f64 ? ScalarType::kFloat64 : ScalarType::kFloat32;
  layout = AttributeLayout{};
  layout.scalars = {{"c", ScalarType::kFloat32}, {"u", uv_type, uint8_t(bits)}, {"v", uv_type, uint8_t(bits)}};
  QuantizedMesh q;
  const double cell = 4000.0 / n;
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < n; ++j) {
      const double x = (j + (j > 0 && j < n - 1 ? jitter(rng) : 0)) / (n - 1),
                   y = (i + (i > 0 && i < n - 1 ? jitter(rng) : 0)) / (n - 1);
      const double z = 0.05 * std::sin(3 * x) * std::cos(2 * y);
      q.positions.push_back({uint32_t(std::lround(50 + x * cell * (n - 1))),
                             uint32_t(std::lround(50 + y * cell * (n - 1))),
                             uint32_t(std::lround(2000 + z * cell * (n - 1)))});
      const double u = 0.1 + 0.55 * x + 0.12 * y, v = 0.05 - 0.08 * x + 0.3 * y;
      std::vector<uint32_t> row = {floatBits(float(x * y))};
      for (double t : {mirror && x > 0.5 ? -u : u, v}) {
        if (f64) {
          const uint64_t b = std::bit_cast<uint64_t>(t);
          row.push_back(uint32_t(b)), row.push_back(uint32_t(b >> 32));
        } else {
          row.push_back(floatBits(float(t)));
        }
      }
      EXPECT_TRUE(snapScalarRow(layout.scalars, row.data(), q.positions.size() - 1).isOk());
      q.scalars.insert(q.scalars.end(), row.begin(), row.end());
    }
  for (int i = 0; i + 1 < n; ++i)
    for (int j = 0; j + 1 < n; ++j) {
      const uint32_t a = uint32_t(i * n + j), b = a + 1, c = a + uint32_t(n), d = c + 1;
      if (rng() & 1) q.triangles.push_back({a, b, d}), q.triangles.push_back({a, d, c});
      else q.triangles.push_back({a, b, c}), q.triangles.push_back({b, d, c});
    }
  return q;
}

using Row = std::pair<Vec3u, std::vector<uint32_t>>;
std::vector<Row> rows(const QuantizedMesh& m, size_t stride) {
  std::vector<Row> out;
  for (size_t i = 0; i < m.positions.size(); ++i)
    out.emplace_back(m.positions[i],
                     std::vector<uint32_t>(m.scalars.begin() + i * stride, m.scalars.begin() + (i + 1) * stride));
  std::sort(out.begin(), out.end());
  return out;
}

class UvRoundTrip : public ::testing::TestWithParam<CodecId> {
 protected:
  const CodecInfo& codec() const { return *findCodec(GetParam()); }
};

TEST_P(UvRoundTrip, LevelsComeBackBitForBit) {
  for (bool f64 : {false, true})
    for (int bits : {1, 8, 12, 24}) {
      SCOPED_TRACE(std::string(f64 ? "float64" : "float32") + " at " + std::to_string(bits) + " bits");
      AttributeLayout layout;
      const QuantizedMesh q = chart(24, bits, true, f64, layout);
      const TileContext ctx{12, layout};
      auto enc = encodeMesh(codec(), ctx, q);
      ASSERT_TRUE(enc.isOk()) << enc.status().toString();
      auto d = codec().decode(ctx, payloadVersion(codec(), *enc), enc->payload, limitsOf(enc->decoded));
      ASSERT_TRUE(d.isOk()) << d.status().toString();
      const size_t stride = size_t(layout.scalarStride());
      EXPECT_TRUE(rows(*d, stride) == rows(q, stride));
    }
}

// A fan of 3000 triangles around one hub vertex (a large polygon, fan-triangulated by a reader), its rim a circle in
// texture space: every level comes back (the search across an edge looks at the rim vertex's short list, not the
// hub's).
TEST_P(UvRoundTrip, FansAroundAHubComeBack) {
  AttributeLayout layout;
  layout.scalars = {{"u", ScalarType::kFloat32, 12}, {"v", ScalarType::kFloat32, 12}};
  QuantizedMesh q;
  const int rim = 3000;
  q.positions.push_back({2048, 2048, 2048});
  q.scalars.insert(q.scalars.end(), {floatBits(0.5f), floatBits(0.5f)});
  for (int i = 0; i < rim; ++i) {
    const double a = 2 * M_PI * i / rim;
    q.positions.push_back({uint32_t(std::lround(2048 + 1900 * std::cos(a))),
                           uint32_t(std::lround(2048 + 1900 * std::sin(a))), uint32_t(2048 + (i % 7))});
    std::vector<uint32_t> row = {floatBits(float(0.5 + 0.4 * std::cos(a))), floatBits(float(0.5 + 0.3 * std::sin(a)))};
    ASSERT_TRUE(snapScalarRow(layout.scalars, row.data(), size_t(i)).isOk());
    q.scalars.insert(q.scalars.end(), row.begin(), row.end());
  }
  for (int i = 0; i < rim; ++i) q.triangles.push_back({0, uint32_t(1 + i), uint32_t(1 + (i + 1) % rim)});
  const TileContext ctx{12, layout};
  auto enc = encodeMesh(codec(), ctx, q);
  ASSERT_TRUE(enc.isOk()) << enc.status().toString();
  auto d = codec().decode(ctx, payloadVersion(codec(), *enc), enc->payload, limitsOf(enc->decoded));
  ASSERT_TRUE(d.isOk()) << d.status().toString();
  EXPECT_TRUE(rows(*d, 2) == rows(q, 2));
}

TEST_P(UvRoundTrip, EncoderRefusesValuesOffTheirLevels) {
  AttributeLayout layout;
  QuantizedMesh q = chart(8, 12, false, false, layout);
  q.scalars[3 * 5 + 1] = floatBits(std::bit_cast<float>(q.scalars[3 * 5 + 1]) + 1e-5f);  // vertex 5's u
  auto enc = encodeMesh(codec(), TileContext{12, layout}, q);
  if (GetParam() == CodecId::kStore) {
    // store keeps values raw at their type: off-level values come back as they are.
    ASSERT_TRUE(enc.isOk()) << enc.status().toString();
    return;
  }
  ASSERT_FALSE(enc.isOk());
  EXPECT_NE(enc.status().message().find("u of vertex 5"), std::string::npos) << enc.status().toString();
}

INSTANTIATE_TEST_SUITE_P(Codecs, UvRoundTrip,
                         ::testing::Values(CodecId::kStore, CodecId::kKdtree, CodecId::kOctree, CodecId::kEdgebreaker),
                         [](const ::testing::TestParamInfo<CodecId>& info) {
  return std::string(findCodec(info.param)->name);
});

// The texture-space prediction: on the affine chart (mirrored on half of it) the levels cost a few bits per vertex,
// under half of what the same levels cost under other names (channels p and q, which are not texture coordinates
// and are predicted by their neighbours' mean, as every other channel).
TEST(UvBits, AffineChartsArePredictedFromTheirGeometry) {
  for (CodecId id : {CodecId::kEdgebreaker, CodecId::kKdtree}) {
    const CodecInfo& codec = *findCodec(id);
    for (bool mirror : {false, true}) {
      AttributeLayout layout;
      const QuantizedMesh q = chart(64, 12, mirror, false, layout);
      AttributeLayout renamed = layout;
      renamed.scalars[1].name = "p", renamed.scalars[2].name = "q";
      AttributeLayout without = layout;
      without.scalars.resize(1);
      QuantizedMesh bare = q;
      bare.scalars.clear();
      for (size_t v = 0; v < q.positions.size(); ++v) bare.scalars.push_back(q.scalars[v * 3]);
      auto a = encodeMesh(codec, TileContext{12, layout}, q);
      auto b = encodeMesh(codec, TileContext{12, renamed}, q);
      auto c = encodeMesh(codec, TileContext{12, without}, bare);
      ASSERT_TRUE(a.isOk() && b.isOk() && c.isOk());
      const double n = double(q.positions.size());
      const double predicted = 8.0 * double(a->payload.size() - c->payload.size()) / n;
      const double by_mean = 8.0 * double(b->payload.size() - c->payload.size()) / n;
      std::printf("%s%s: 12-bit texture coordinates %.2f bits per vertex (by the neighbours' mean: %.2f)\n",
                  codec.name.data(), mirror ? ", mirrored half" : "", predicted, by_mean);
      EXPECT_LT(predicted, 7.0);
      EXPECT_LT(predicted, 0.6 * by_mean);
    }
  }
}

// Version 3: the channels' bits and the material names; v2 and v1 are still written when neither is needed.
TEST(UvBits, ContainerVersion3HoldsBitsAndMaterials) {
  AttributeLayout layout;
  const QuantizedMesh q = chart(16, 10, false, false, layout);
  const Grid grid{{0, 0, 0}, 1.0, 12};
  const auto write = [&](const AttributeLayout& l, const QuantizedMesh& m, const std::string& library,
                         const std::string& material) -> Result<std::vector<uint8_t>> {
    std::vector<uint8_t> out;
    VectorSink sink(out);
    ContainerWriter writer(sink, grid, l);
    SP_RETURN_IF_ERROR(writer.setMaterial({library, material, {}}));
    SP_RETURN_IF_ERROR(writer.begin());
    SP_ASSIGN_OR_RETURN(EncodedTile tile, encodeMesh(*findCodec(CodecId::kEdgebreaker), TileContext{12, l}, m));
    SP_RETURN_IF_ERROR(writer.addTile(0, *findCodec(CodecId::kEdgebreaker), tile));
    SP_RETURN_IF_ERROR(writer.finish());
    return out;
  };
  const std::string library = "scan textures.mtl", material = "Ma\xC3\x9F_1";  // UTF-8 kept
  auto file = write(layout, q, library, material);
  ASSERT_TRUE(file.isOk()) << file.status().toString();
  auto pc = parseContainer(*file, "mem");
  ASSERT_TRUE(pc.isOk()) << pc.status().toString();
  EXPECT_EQ(pc->header.version, 3u);
  EXPECT_EQ(pc->header.layout, layout);
  EXPECT_EQ(pc->header.materials.library, library);
  EXPECT_EQ(pc->header.materials.material, material);
  EXPECT_EQ(pc->header.header_size, kHeaderSize + 1 + 3 * 3 + 3 + 6 + library.size() + material.size() + 4);
  EXPECT_TRUE(pc->header.materials.texture.empty());
  // Materials alone, without any channel: version 3 with an empty table.
  QuantizedMesh plain = q;
  plain.scalars.clear();
  auto only = write(AttributeLayout{}, plain, "", "skin");
  ASSERT_TRUE(only.isOk()) << only.status().toString();
  auto po = parseContainer(*only, "mem");
  ASSERT_TRUE(po.isOk()) << po.status().toString();
  EXPECT_EQ(po->header.version, 3u);
  EXPECT_EQ(po->header.materials.material, "skin");
  EXPECT_TRUE(po->header.materials.library.empty());
  // Lossless channels and no material: version 2, byte for byte as before.
  AttributeLayout lossless = layout;
  for (ScalarChannel& c : lossless.scalars) c.bits = 0;
  auto v2 = write(lossless, q, "", "");
  ASSERT_TRUE(v2.isOk());
  EXPECT_EQ(parseContainer(*v2, "mem")->header.version, 2u);
  // Refused by the writer: bits on an integer channel, beyond 24, a material name with a control character or too
  // long.
  AttributeLayout int_bits;
  int_bits.scalars = {{"q", ScalarType::kUint16, 4}};
  QuantizedMesh qi = plain;
  qi.scalars.assign(qi.positions.size(), 0);
  EXPECT_FALSE(write(int_bits, qi, "", "").isOk());
  AttributeLayout wide = layout;
  wide.scalars[1].bits = wide.scalars[2].bits = 25;
  EXPECT_FALSE(write(wide, q, "", "").isOk());
  EXPECT_FALSE(write(layout, q, "a\nb", "").isOk());
  for (const char* bad : {"caf\xE9.mtl", "\xC0\xAF", "\xED\xA0\x80", "\xF4\x90\x80\x80", "\xE2\x82"})
    EXPECT_FALSE(write(layout, q, bad, "").isOk()) << bad;  // Latin-1, overlong, surrogate, above U+10FFFF, cut
  EXPECT_TRUE(write(layout, q, "\xF0\x9F\x98\x80.mtl", "").isOk());
  {
    std::vector<uint8_t> out;
    VectorSink sink(out);
    ContainerWriter writer(sink, grid, layout);
    ASSERT_TRUE(writer.begin().isOk());
    EXPECT_EQ(writer.setMaterial({"late.mtl", "", ""}).code(), ErrorCode::kInternal);
  }
  EXPECT_FALSE(write(layout, q, "", std::string(kMaxMaterialBytes + 1, 'm')).isOk());
  EXPECT_TRUE(write(layout, q, "", std::string(kMaxMaterialBytes, 'm')).isOk());
}

// Hostile version 3 tables, checksums repaired so that the parser itself must refuse them: every byte of the
// table set to values near the truth and to extremes; nothing accepted that does not parse, every accepted
// header's tiles decode or fail cleanly.
TEST(UvBits, HostileVersion3TablesFailCleanly) {
  AttributeLayout layout;
  const QuantizedMesh q = chart(12, 12, false, false, layout);
  std::vector<uint8_t> file;
  {
    VectorSink sink(file);
    ContainerWriter writer(sink, Grid{{0, 0, 0}, 1.0, 12}, layout);
    ASSERT_TRUE(writer.setMaterial({"a.mtl", "m", ""}).isOk());
    ASSERT_TRUE(writer.begin().isOk());
    auto tile = encodeMesh(*findCodec(CodecId::kKdtree), TileContext{12, layout}, q);
    ASSERT_TRUE(tile.isOk());
    ASSERT_TRUE(writer.addTile(0, *findCodec(CodecId::kKdtree), *tile).isOk());
    ASSERT_TRUE(writer.finish().isOk());
  }
  auto pc = parseContainer(file, "mem");
  ASSERT_TRUE(pc.isOk()) << pc.status().toString();
  const auto [refused, tried] = mutateHeaderTable(file, {0, 1, 7, 24, 25, 31, 255, 256, -1},
                                                  [](const ContainerHeader& h) {
    for (const ScalarChannel& c : h.layout.scalars) {
      EXPECT_LE(c.bits, kMaxScalarBits);
      if (c.bits) {
        EXPECT_TRUE(isFloatScalar(c.type));
      }
    }
    EXPECT_TRUE(validMaterialName(h.materials.library) && validMaterialName(h.materials.material) &&
                validMaterialName(h.materials.texture));
  });
  EXPECT_GT(refused, tried / 4);
  // A version 2 reader's view: the same table read as version 2 does not parse.
  std::vector<uint8_t> b = file;
  b[8] = 2;
  const uint32_t crc = crc32c(std::span(b).first(kHeaderSize - 4));
  std::memcpy(b.data() + kHeaderSize - 4, &crc, 4);
  EXPECT_FALSE(parseContainer(b, "mem").isOk());
}

// Golden containers of version 3 (tests/golden/uv-<codec>.spz, kept forever): each build decodes them to the chart
// they were made from, and the writer must still produce them byte for byte (the levels' coding and the texture
// prediction are part of the format). SCANPRESS_WRITE_GOLDEN=1 writes the missing ones.
TEST(UvBits, GoldenContainersDecodeAndAreReproduced) {
  AttributeLayout layout;
  const QuantizedMesh q = chart(10, 12, true, false, layout, 11);
  const Grid grid{{0, 0, 0}, 1.0, 12};
  for (CodecId id : {CodecId::kStore, CodecId::kKdtree, CodecId::kOctree, CodecId::kEdgebreaker}) {
    const CodecInfo& codec = *findCodec(id);
    SCOPED_TRACE(codec.name);
    const std::string path = std::string(SCANPRESS_GOLDEN) + "/uv-" + std::string(codec.name) + ".spz";
    std::vector<uint8_t> bytes;
    {
      VectorSink sink(bytes);
      ContainerWriter writer(sink, grid, layout);
      ASSERT_TRUE(writer.setMaterial({"chart.mtl", "chart", ""}).isOk());
      ASSERT_TRUE(writer.begin().isOk());
      auto tile = encodeMesh(codec, TileContext{12, layout}, q);
      ASSERT_TRUE(tile.isOk()) << tile.status().toString();
      ASSERT_TRUE(writer.addTile(0, codec, *tile).isOk());
      ASSERT_TRUE(writer.finish().isOk());
    }
    if (!std::filesystem::exists(path) && std::getenv("SCANPRESS_WRITE_GOLDEN")) {
      testing::writeBytes(path, std::string(bytes.begin(), bytes.end()));
    }
    const std::vector<uint8_t> golden = testing::readBytes(path);
    ASSERT_FALSE(golden.empty()) << path << " missing (SCANPRESS_WRITE_GOLDEN=1 writes it)";
    EXPECT_TRUE(golden == bytes) << "the writer no longer reproduces " << path;
    auto pc = parseContainer(golden, path);
    ASSERT_TRUE(pc.isOk()) << pc.status().toString();
    EXPECT_EQ(pc->header.materials.material, "chart");
    const TileEntry& e = pc->tiles.at(0);
    auto payload = parseTileChunk(std::span(golden).subspan(e.offset, e.chunk_bytes), e, path);
    ASSERT_TRUE(payload.isOk());
    auto d = decodeTilePayload(pc->header, e, *payload, path);
    ASSERT_TRUE(d.isOk()) << d.status().toString();
    EXPECT_TRUE(rows(*d, 3) == rows(q, 3));
  }
}

}  // namespace uv

}  // namespace
}  // namespace scanpress
