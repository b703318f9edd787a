// Reading containers from files (jobs/container_file.h): one tile decodes without the others, and a bad tile's
// error names the tile and the file.
#include <gtest/gtest.h>

#include <regex>

#include "engine/container/container.h"
#include "jobs/container_file.h"
#include "container_fixture.h"
#include "sweep_util.h"
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

namespace scanpress {
namespace {

// Issue 18 item 8: every error from reading a container names the file and where in it: a byte offset, or the
// tile (whose payload errors give the offset within the payload). The malformation sweep's mutations, evenly
// sampled per family and container, through every way a command reads a container.
TEST(Container, EveryReadErrorNamesTheFileAndAnOffsetOrATile) {
  testing::TempDir dir;
  const std::string path = dir.file("m.spz");
  const std::regex where("byte [0-9]+|tile [0-9]+");
  uint64_t errors = 0, seed = 4100;
  auto check = [&](const Status& s, const std::string& what) {
    if (s.isOk()) return;
    ++errors;
    EXPECT_NE(s.message().find(path), std::string::npos) << what << ": " << s.message();
    EXPECT_TRUE(std::regex_search(s.message(), where)) << what << ": " << s.message();
  };
  for (const sweep::SweepContainer& c : sweep::sweepContainers())
    for (const sweep::Family family : sweep::kFamilies) {
#if defined(__SANITIZE_ADDRESS__)
      constexpr uint64_t kPerFamily = 10;  // ASan: the decoders run under the sweep and the fuzz lane too
#else
      constexpr uint64_t kPerFamily = 60;
#endif
      uint64_t count = 0, i = 0, next = 0, taken = 0;
      sweep::forEachMutation(c.bytes, family, ++seed, 200, [&](const std::vector<uint8_t>&) { ++count; });
      sweep::forEachMutation(c.bytes, family, seed, 200, [&](const std::vector<uint8_t>& bytes) {
        if (i++ != next || taken == kPerFamily) return;
        next = ++taken * count / kPerFamily;
        const std::string what = c.name + ", " + sweep::familyName(family) + " #" + std::to_string(i - 1);
        testing::writeBytes(path, std::string(bytes.begin(), bytes.end()));
        auto file = ContainerFile::open(path);
        if (!file.isOk()) return check(file.status(), what + ", open");
        check(file->verifyChecksums(), what + ", verify");
        for (const TileEntry& e : file->tiles()) {
          check(file->decodeTile(e).status(), what + ", decode");
          auto levels = file->tileLevels(e);
          check(levels.status(), what + ", levels");
          if (levels.isOk() && !levels->empty()) check(file->decodeTile(e, 0u).status(), what + ", level 0");
        }
      });
    }
  std::printf("%llu errors, each naming the file and an offset or tile\n", static_cast<unsigned long long>(errors));
  EXPECT_GT(errors, 1000u);
}

}  // namespace
}  // namespace scanpress
