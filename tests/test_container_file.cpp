// Reading containers from files (jobs/container_file.h): one tile decodes without the others, and a bad tile's
// error names the tile and the file.
#include <gtest/gtest.h>

#include "engine/container/container.h"
#include "jobs/container_file.h"
#include "test_util.h"

namespace scanpress {
namespace {

struct Fixture {
  Grid grid;
  AttributeLayout layout{12, 4};
  std::vector<QuantizedMesh> tiles;
  std::vector<uint8_t> bytes;
};

Fixture makeFixture(int tile_count = 2) {
  Fixture f;
  Mesh m = testing::octahedron(2.0);
  for (size_t i = 0; i < m.positions.size(); ++i) {
    const auto& p = m.positions[i];
    m.normals.push_back({static_cast<float>(p[0] / 2), static_cast<float>(p[1] / 2), static_cast<float>(p[2] / 2)});
    m.colors.push_back({static_cast<uint8_t>(40 * i), 7, 200, 255});
  }
  m.color_channels = 4;
  f.grid = *makeGrid(boundingBox(m), 12);
  auto q = quantizeMesh(m, f.grid, f.layout, nullptr);
  for (int t = 0; t < tile_count; ++t) f.tiles.push_back(*q);
  f.bytes = *encodeContainer(f.grid, f.layout, *findCodec(CodecId::kStore), f.tiles);
  return f;
}

TEST(Container, OneTileReadsWithoutTheOthers) {
  Fixture f = makeFixture(3);
  testing::TempDir dir;
  const std::string path = dir.file("c.spz");
  testing::writeBytes(path, std::string(f.bytes.begin(), f.bytes.end()));
  // Corrupt tile 0's payload: tile 2 must still decode, tile 0 must fail naming itself.
  auto pc = parseContainer(f.bytes, "mem");
  auto bytes = f.bytes;
  bytes[pc->tiles[0].offset + kChunkHeaderSize + 3] ^= 0x10;
  testing::writeBytes(path, std::string(bytes.begin(), bytes.end()));
  auto file = ContainerFile::open(path);
  ASSERT_TRUE(file.isOk());
  EXPECT_TRUE(file->decodeTile(file->tiles()[2]).isOk());
  auto bad = file->decodeTile(file->tiles()[0]);
  ASSERT_FALSE(bad.isOk());
  EXPECT_EQ(bad.status().code(), ErrorCode::kChecksum);
  EXPECT_NE(bad.status().message().find("tile 0"), std::string::npos) << bad.status().message();
  EXPECT_NE(bad.status().message().find(path), std::string::npos);
}

}  // namespace
}  // namespace scanpress
