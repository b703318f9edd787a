// Reading containers from files (jobs/container_file.h): one tile decodes without the others, and a bad tile's
// error names the tile and the file.
#include <gtest/gtest.h>

#include "engine/container/container.h"
#include "jobs/container_file.h"
#include "container_fixture.h"
#include "test_util.h"

namespace scanpress {
namespace {

TEST(Container, OneTileReadsWithoutTheOthers) {
  testing::ContainerFixture f = testing::makeContainerFixture(3);
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
