// Quantized texture coordinates (issue 22 part 3, `--uv-bits`): a float channel with ScalarChannel::bits keeps
// multiples of 2^-bits and codecs code the multiple. Checked here: snapScalar against direct rounding and its
// refusals; bit-exact round trips of the levels through every codec that carries scalars, float32 and float64, at
// 1 to 24 bits, beside a lossless channel; encoders refusing values off their levels; the texture-space prediction
// on an irregular, anisotropic, partly mirrored chart; the container's version 3 header (channel bits and material
// names) against hostile bytes; and golden version 3 containers.
#include <gtest/gtest.h>

#include <bit>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <limits>
#include <random>

#include "engine/codecs/codec.h"
#include "engine/container/container.h"
#include "engine/io/crc32c.h"
#include "engine/quantize.h"
#include "engine/shapes.h"
#include "test_util.h"

namespace scanpress {
namespace {

uint32_t floatBits(float f) { return std::bit_cast<uint32_t>(f); }

TEST(UvBits, SnapScalarIsRoundingToMultiplesOfItsStep) {
  std::mt19937_64 rng(7);
  for (ScalarType type : {ScalarType::kFloat32, ScalarType::kFloat64})
    for (int bits : {1, 5, 12, 16, 24}) {
      const ScalarChannel c{"u", type, uint8_t(bits)};
      const double step = std::ldexp(1.0, -bits), limit = std::ldexp(1.0, 31 - bits);
      for (int i = 0; i < 20000; ++i) {
        // Values of every magnitude up to the limit, of both signs.
        const double magnitude = std::ldexp(double(rng() % 1000000) / 1e6, int(rng() % 40) - 10);
        const double x = (rng() & 1 ? -1 : 1) * std::min(magnitude, limit * 0.999);
        uint32_t w[2] = {0, 0};
        if (type == ScalarType::kFloat32) {
          w[0] = floatBits(float(x));
        } else {
          const uint64_t b = std::bit_cast<uint64_t>(x);
          w[0] = uint32_t(b), w[1] = uint32_t(b >> 32);
        }
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
        if (type == ScalarType::kFloat32) {
          w[0] = floatBits(float(bad));
        } else {
          const uint64_t b = std::bit_cast<uint64_t>(bad);
          w[0] = uint32_t(b), w[1] = uint32_t(b >> 32);
        }
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
      auto d = codec().decode(ctx, codec().version, enc->payload, limitsOf(enc->decoded));
      ASSERT_TRUE(d.isOk()) << d.status().toString();
      const size_t stride = size_t(layout.scalarStride());
      EXPECT_TRUE(rows(*d, stride) == rows(q, stride));
    }
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
    writer.setMaterial(library, material);
    SP_RETURN_IF_ERROR(writer.begin());
    SP_ASSIGN_OR_RETURN(EncodedTile tile, encodeMesh(*findCodec(CodecId::kEdgebreaker), TileContext{12, l}, m));
    SP_RETURN_IF_ERROR(writer.addTile(0, *findCodec(CodecId::kEdgebreaker), tile.decoded, tile.payload));
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
  EXPECT_EQ(pc->header.material_library, library);
  EXPECT_EQ(pc->header.material, material);
  EXPECT_EQ(pc->header.header_size, kHeaderSize + 1 + 3 * 3 + 3 + 4 + library.size() + material.size() + 4);
  // Materials alone, without any channel: version 3 with an empty table.
  QuantizedMesh plain = q;
  plain.scalars.clear();
  auto only = write(AttributeLayout{}, plain, "", "skin");
  ASSERT_TRUE(only.isOk()) << only.status().toString();
  auto po = parseContainer(*only, "mem");
  ASSERT_TRUE(po.isOk()) << po.status().toString();
  EXPECT_EQ(po->header.version, 3u);
  EXPECT_EQ(po->header.material, "skin");
  EXPECT_TRUE(po->header.material_library.empty());
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
    writer.setMaterial("a.mtl", "m");
    ASSERT_TRUE(writer.begin().isOk());
    auto tile = encodeMesh(*findCodec(CodecId::kKdtree), TileContext{12, layout}, q);
    ASSERT_TRUE(tile.isOk());
    ASSERT_TRUE(writer.addTile(0, *findCodec(CodecId::kKdtree), tile->decoded, tile->payload).isOk());
    ASSERT_TRUE(writer.finish().isOk());
  }
  auto pc = parseContainer(file, "mem");
  ASSERT_TRUE(pc.isOk()) << pc.status().toString();
  const size_t hs = pc->header.header_size;
  size_t refused = 0, tried = 0;
  for (size_t at = kHeaderSize; at + 4 < hs; ++at)
    for (const int v : std::vector<int>{0, 1, 7, 24, 25, 31, 255, int(file[at]) + 1, int(file[at]) - 1}) {
      std::vector<uint8_t> b = file;
      b[at] = uint8_t(v);
      const uint32_t crc = crc32c(std::span(b).subspan(kHeaderSize, hs - kHeaderSize - 4));
      std::memcpy(b.data() + hs - 4, &crc, 4);
      auto r = parseContainer(b, "mem");
      ++tried;
      if (!r.isOk()) {
        ++refused;
        EXPECT_NE(r.status().message().find("mem"), std::string::npos);
        continue;
      }
      for (const ScalarChannel& c : r->header.layout.scalars) {
        EXPECT_LE(c.bits, kMaxScalarBits);
        if (c.bits) {
          EXPECT_TRUE(isFloatScalar(c.type));
        }
      }
      EXPECT_TRUE(validMaterialName(r->header.material_library) && validMaterialName(r->header.material));
      for (const TileEntry& e : r->tiles) {
        auto payload = parseTileChunk(std::span(b).subspan(e.offset, e.chunk_bytes), e, "mem");
        if (payload.isOk()) (void)decodeTilePayload(r->header, e, *payload, "mem");
      }
    }
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
      writer.setMaterial("chart.mtl", "chart");
      ASSERT_TRUE(writer.begin().isOk());
      auto tile = encodeMesh(codec, TileContext{12, layout}, q);
      ASSERT_TRUE(tile.isOk()) << tile.status().toString();
      ASSERT_TRUE(writer.addTile(0, codec, tile->decoded, tile->payload).isOk());
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
    EXPECT_EQ(pc->header.material, "chart");
    const TileEntry& e = pc->tiles.at(0);
    auto payload = parseTileChunk(std::span(golden).subspan(e.offset, e.chunk_bytes), e, path);
    ASSERT_TRUE(payload.isOk());
    auto d = decodeTilePayload(pc->header, e, *payload, path);
    ASSERT_TRUE(d.isOk()) << d.status().toString();
    EXPECT_TRUE(rows(*d, 3) == rows(q, 3));
  }
}

}  // namespace
}  // namespace scanpress
