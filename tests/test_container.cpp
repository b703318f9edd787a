#include <gtest/gtest.h>

#include <cstring>
#include <random>

#include "engine/container/container.h"
#include "engine/io/crc32c.h"
#include "container_fixture.h"
#include "test_util.h"

namespace scanpress {
namespace {

// Full decode of an in-memory container: header, footer, index, every tile.
Status decodeAll(std::span<const uint8_t> file) {
  auto pc = parseContainer(file, "mem");
  if (!pc.isOk()) return pc.status();
  for (const auto& e : pc->tiles) {
    auto payload = parseTileChunk(file.subspan(e.offset, e.chunk_bytes), e, "mem");
    if (!payload.isOk()) return payload.status();
    auto mesh = decodeTilePayload(pc->header, e, *payload, "mem");
    if (!mesh.isOk()) return mesh.status();
  }
  return Status::ok();
}

TEST(Container, RoundTripsTilesWithAttributes) {
  testing::ContainerFixture f = testing::makeContainerFixture(3);
  auto pc = parseContainer(f.bytes, "mem");
  ASSERT_TRUE(pc.isOk()) << pc.status().toString();
  EXPECT_EQ(pc->header.tile_count, 3u);
  EXPECT_EQ(pc->header.vertices, 18u);
  EXPECT_EQ(pc->header.faces, 24u);
  EXPECT_EQ(pc->header.layout, f.layout);
  EXPECT_EQ(pc->header.grid.bits, 12);
  EXPECT_EQ(pc->header.grid.cell, f.grid.cell);
  for (const auto& e : pc->tiles) {
    auto payload = parseTileChunk(std::span(f.bytes).subspan(e.offset, e.chunk_bytes), e, "mem");
    ASSERT_TRUE(payload.isOk());
    auto mesh = decodeTilePayload(pc->header, e, *payload, "mem");
    ASSERT_TRUE(mesh.isOk()) << mesh.status().toString();
    EXPECT_EQ(mesh->positions, f.tiles[e.tile_id].positions);
    EXPECT_EQ(mesh->triangles, f.tiles[e.tile_id].triangles);
    EXPECT_EQ(mesh->normals, f.tiles[e.tile_id].normals);
    EXPECT_EQ(mesh->colors, f.tiles[e.tile_id].colors);
  }
}

TEST(Container, EveryTruncationIsRejected) {
  testing::ContainerFixture f = testing::makeContainerFixture(2);
  ASSERT_TRUE(decodeAll(f.bytes).isOk());
  for (size_t len = 0; len < f.bytes.size(); ++len) {
    std::vector<uint8_t> cut(f.bytes.begin(), f.bytes.begin() + static_cast<ptrdiff_t>(len));
    Status s = decodeAll(cut);
    ASSERT_FALSE(s.isOk()) << "truncation to " << len << " bytes was accepted";
    EXPECT_FALSE(s.message().empty());
  }
}

TEST(Container, EveryFlippedByteIsRejected) {
  testing::ContainerFixture f = testing::makeContainerFixture(2);
  for (size_t i = 0; i < f.bytes.size(); ++i) {
    for (uint8_t mask : {uint8_t{0x01}, uint8_t{0x80}, uint8_t{0xFF}}) {
      auto bytes = f.bytes;
      bytes[i] ^= mask;
      Status s = decodeAll(bytes);
      ASSERT_FALSE(s.isOk()) << "flip of byte " << i << " with mask " << int(mask) << " was accepted";
    }
  }
}

// Rewrites a header field and fixes the header checksum, to reach the checks behind it.
void patchHeader(std::vector<uint8_t>& bytes, size_t offset, const void* value, size_t n) {
  std::memcpy(bytes.data() + offset, value, n);
  const uint32_t crc = crc32c(std::span(bytes).first(kHeaderSize - 4));
  std::memcpy(bytes.data() + kHeaderSize - 4, &crc, 4);
}

// Byte 51 holds the color bits (0: 8). A container at fewer bits names them and decodes to its colors; a nonzero
// byte without colors, or above 7, is malformed.
TEST(Container, ColorBitsAreKeptAndChecked) {
  testing::ContainerFixture f = testing::makeContainerFixture(1);
  EXPECT_EQ(f.bytes[51], 0);
  auto parsed = parseContainer(f.bytes, "mem");
  ASSERT_TRUE(parsed.isOk());
  EXPECT_EQ(parsed->header.layout.color_bits, 8);

  AttributeLayout layout = f.layout;
  layout.color_bits = 5;
  QuantizedMesh tile = f.tiles[0];
  for (auto& c : tile.colors) c = quantizeColor(c, layout);
  const QuantizedMesh tiles[] = {tile};
  for (CodecId id : {CodecId::kStore, CodecId::kKdtree, CodecId::kEdgebreaker}) {
    auto bytes = encodeContainer(f.grid, layout, *findCodec(id), tiles);
    ASSERT_TRUE(bytes.isOk()) << bytes.status().toString();
    EXPECT_EQ((*bytes)[51], 5);
    auto pc = parseContainer(*bytes, "mem");
    ASSERT_TRUE(pc.isOk()) << pc.status().toString();
    EXPECT_TRUE(pc->header.layout == layout);
    const auto& e = pc->tiles[0];
    auto payload = parseTileChunk(std::span(*bytes).subspan(e.offset, e.chunk_bytes), e, "mem");
    ASSERT_TRUE(payload.isOk());
    auto mesh = decodeTilePayload(pc->header, e, *payload, "mem");
    ASSERT_TRUE(mesh.isOk()) << mesh.status().toString();
    auto sorted = [](std::vector<Rgba8> v) {
      std::sort(v.begin(), v.end());
      return v;
    };
    EXPECT_EQ(sorted(mesh->colors), sorted(tile.colors));
  }

  for (uint8_t bad : {uint8_t{8}, uint8_t{9}, uint8_t{255}}) {
    auto bytes = f.bytes;
    patchHeader(bytes, 51, &bad, 1);
    EXPECT_EQ(decodeAll(bytes).code(), ErrorCode::kMalformed) << int(bad);
  }
  // Without colors the byte must stay 0.
  AttributeLayout bare{12, 0};
  QuantizedMesh plain = f.tiles[0];
  plain.colors.clear();
  const QuantizedMesh plain_tiles[] = {plain};
  auto bytes = *encodeContainer(f.grid, bare, *findCodec(CodecId::kStore), plain_tiles);
  EXPECT_TRUE(decodeAll(bytes).isOk());
  const uint8_t five = 5;
  patchHeader(bytes, 51, &five, 1);
  EXPECT_EQ(decodeAll(bytes).code(), ErrorCode::kMalformed);
}

TEST(Container, UnknownVersionAndCodecAreTheirOwnErrors) {
  testing::ContainerFixture f = testing::makeContainerFixture(1);
  auto bytes = f.bytes;
  const uint32_t v4 = 4;
  patchHeader(bytes, 8, &v4, 4);
  EXPECT_EQ(decodeAll(bytes).code(), ErrorCode::kUnknownVersion);
  // Version 2 (scalar channels) needs its channel table: an 80-byte header is malformed.
  bytes = f.bytes;
  const uint32_t v2 = 2;
  patchHeader(bytes, 8, &v2, 4);
  EXPECT_EQ(decodeAll(bytes).code(), ErrorCode::kMalformed);

  // Codec id 999 in both the index and the chunk header, with all checksums fixed up.
  bytes = f.bytes;
  auto pc = parseContainer(bytes, "mem");
  const uint16_t codec = 999;
  const auto& e = pc->tiles[0];
  std::memcpy(bytes.data() + e.offset + 8, &codec, 2);
  uint32_t crc = crc32c(std::span(bytes).subspan(e.offset, kChunkHeaderSize - 4));
  std::memcpy(bytes.data() + e.offset + kChunkHeaderSize - 4, &crc, 4);
  const uint64_t index_offset = bytes.size() - kFooterSize - (12 + kIndexEntrySize);
  std::memcpy(bytes.data() + index_offset + 8 + 4, &codec, 2);
  crc = crc32c(std::span(bytes).subspan(index_offset, 8 + kIndexEntrySize));
  std::memcpy(bytes.data() + index_offset + 8 + kIndexEntrySize, &crc, 4);
  Status s = decodeAll(bytes);
  EXPECT_EQ(s.code(), ErrorCode::kUnknownCodec) << s.toString();

  // Unknown codec version of a known codec.
  bytes = f.bytes;
  const uint16_t version = 77;
  std::memcpy(bytes.data() + e.offset + 10, &version, 2);
  crc = crc32c(std::span(bytes).subspan(e.offset, kChunkHeaderSize - 4));
  std::memcpy(bytes.data() + e.offset + kChunkHeaderSize - 4, &crc, 4);
  std::memcpy(bytes.data() + index_offset + 8 + 6, &version, 2);
  crc = crc32c(std::span(bytes).subspan(index_offset, 8 + kIndexEntrySize));
  std::memcpy(bytes.data() + index_offset + 8 + kIndexEntrySize, &crc, 4);
  EXPECT_EQ(decodeAll(bytes).code(), ErrorCode::kUnknownVersion);
}

TEST(StoreCodec, HostilePayloadsFailCleanly) {
  testing::ContainerFixture f = testing::makeContainerFixture(1);
  TileContext ctx{f.grid.bits, f.layout};
  auto encoded = encodeMesh(*findCodec(CodecId::kStore), ctx, f.tiles[0]);
  ASSERT_TRUE(encoded.isOk());
  const std::vector<uint8_t>& payload = encoded->payload;
  const DecodeLimits limits = limitsOf(encoded->decoded);
  // Every truncation, and random garbage, with no checksum in front: the decoder itself must hold.
  for (size_t len = 0; len < payload.size(); ++len) {
    std::vector<uint8_t> cut(payload.begin(), payload.begin() + static_cast<ptrdiff_t>(len));
    EXPECT_FALSE(storeDecode(ctx, 1, cut, limits).isOk());
  }
  std::mt19937 rng(4);
  for (int i = 0; i < 2000; ++i) {
    auto bytes = payload;
    for (int k = 0; k < 3; ++k) bytes[rng() % bytes.size()] = static_cast<uint8_t>(rng());
    auto r = storeDecode(ctx, 1, bytes, limits);
    if (r.isOk()) {
      EXPECT_TRUE(validateTile(ctx, *r).isOk());
    }
  }
  // Counts that promise more than the payload holds are rejected before allocating.
  std::vector<uint8_t> huge = {0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF};
  EXPECT_EQ(storeDecode(ctx, 1, huge, limits).status().code(), ErrorCode::kMalformed);  // beyond the index
  EXPECT_EQ(storeDecode(ctx, 1, huge, DecodeLimits{UINT32_MAX, UINT32_MAX}).status().code(), ErrorCode::kTruncated);
  EXPECT_EQ(storeDecode(ctx, 2, payload, limits).status().code(), ErrorCode::kUnknownVersion);
}

}  // namespace
}  // namespace scanpress
