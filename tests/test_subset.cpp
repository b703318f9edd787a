// One scan over several processes (issue 23 part 2): `encode --subset i/N` writes partial containers that
// `merge` joins into the container one process writes, byte for byte, for every N (more parts than tiles too), codec
// and thread count; parts are labelled partial wherever they are read; a merge with a part missing, repeated, whole,
// of another split or of another scan fails naming it and writes nothing.
#include <gtest/gtest.h>

#include <cstring>
#include <filesystem>
#include <algorithm>
#include <string>
#include <vector>

#include "engine/io/crc32c.h"
#include "jobs/commands.h"
#include "jobs/container_file.h"
#include "jobs_util.h"

namespace scanpress {
namespace {

namespace fs = std::filesystem;

class Subset : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new testing::TempDir;
    std::string out;
    ASSERT_EQ(testing::runScanpress("synth '" + dir_->file("a.ply") + "' --triangles 60000 --seed 3", &out), 0) << out;
    ASSERT_EQ(testing::runScanpress("synth '" + dir_->file("b.ply") + "' --triangles 60000 --seed 4", &out), 0) << out;
  }
  static void TearDownTestSuite() { delete dir_; }
  static std::string encode(const std::string& in, const std::string& out, const std::string& options) {
    std::string log;
    EXPECT_EQ(testing::runScanpress("encode '" + in + "' '" + out + "' --tile-triangles 2048 --quiet " + options, &log),
              0)
        << log;
    return out;
  }
  static testing::TempDir* dir_;
};
testing::TempDir* Subset::dir_ = nullptr;

TEST_F(Subset, MergedPartsAreByteIdenticalToOneProcess) {
  const std::string in = dir_->file("a.ply");
  for (const char* codec : {"edgebreaker", "kdtree"}) {
    const auto whole = testing::readBytes(encode(in, dir_->file(std::string("whole-") + codec + ".spz"),
                                                 std::string("--codec ") + codec));
    auto file = ContainerFile::open(dir_->file(std::string("whole-") + codec + ".spz"));
    ASSERT_TRUE(file.isOk());
    const uint32_t tiles = file->header().tile_count;
    ASSERT_GT(tiles, 8u);
    // The last: more parts than tiles, some hold none (once: an encode per part; not in the slow sanitizer build).
    std::vector<uint32_t> counts = {2, 3};
#if !defined(__SANITIZE_ADDRESS__)
    if (std::string(codec) == "edgebreaker") counts.push_back(tiles + 5);
#endif
    for (uint32_t n : counts) {
      SCOPED_TRACE(std::string(codec) + " N=" + std::to_string(n));
      std::vector<std::string> parts;
      for (uint32_t i = 0; i < n; ++i) {
        const std::string part = dir_->file("p" + std::to_string(i) + ".spz");
        // Parts on machines of different sizes: the thread count never changes a byte.
        encode(in, part,
               std::string("--codec ") + codec + " --subset " + std::to_string(i) + "/" + std::to_string(n) +
                   " --threads " + (i % 2 ? "1" : "2"));
        auto p = ContainerFile::open(part);
        ASSERT_TRUE(p.isOk()) << p.status().toString();
        EXPECT_EQ(p->header().subset_index, i);
        EXPECT_EQ(p->header().subset_count, n);
        for (const TileEntry& t : p->tiles()) EXPECT_EQ(t.tile_id % n, i);
        parts.push_back(part);
      }
      std::reverse(parts.begin(), parts.end());  // any order
      auto merged = mergeContainers(parts, dir_->file("merged.spz"));
      ASSERT_TRUE(merged.isOk()) << merged.status().toString();
      EXPECT_EQ(merged->tiles, tiles);
      EXPECT_EQ(testing::readBytes(dir_->file("merged.spz")), whole);
      for (const auto& p : parts) fs::remove(p);
    }
  }
}

TEST_F(Subset, PartsAreLabelledAndBadMergesFailNamingThePart) {
  const std::string a = dir_->file("a.ply"), b = dir_->file("b.ply");
  const std::string p0 = encode(a, dir_->file("q0.spz"), "--subset 0/3"),
                    p1 = encode(a, dir_->file("q1.spz"), "--subset 1/3"),
                    p2 = encode(a, dir_->file("q2.spz"), "--subset 2/3");
  const std::string other = encode(b, dir_->file("other1.spz"), "--subset 1/3");
  const std::string half = encode(a, dir_->file("h0.spz"), "--subset 0/2");
  const std::string whole = encode(a, dir_->file("whole.spz"), "");
  std::string out;
  // Read as what they are.
  ASSERT_EQ(testing::runScanpress("info '" + p1 + "'", &out), 0);
  EXPECT_NE(out.find("partial:   part 1 of 3"), std::string::npos) << out;
  ASSERT_EQ(testing::runScanpress("info '" + p1 + "' --json", &out), 0);
  EXPECT_NE(out.find("\"subset\""), std::string::npos) << out;
  ASSERT_EQ(testing::runScanpress("decode '" + p1 + "' '" + dir_->file("p1.ply") + "' --quiet", &out), 0);
  EXPECT_NE(out.find("warning: " + p1 + " is part 1 of 3"), std::string::npos) << out;
  // Bad merges: nothing written, the part named.
  const std::string target = dir_->file("m.spz");
  struct Case {
    std::vector<std::string> parts;
    std::string says;
  };
  for (const Case& c :
       {Case{{p0, p1}, "part 2 of 3 is missing"}, Case{{p0, p1, p1, p2}, "given twice"},
        Case{{p0, p1, whole}, whole + ": a whole container"}, Case{{p0, half, p2}, half + ": part 0 of 2, not of 3"},
        Case{{p0, other, p2}, other + ": another grid"}}) {
    std::string args = "merge";
    for (const auto& p : c.parts) args += " '" + p + "'";
    EXPECT_EQ(testing::runScanpress(args + " '" + target + "'", &out), 1) << args;
    EXPECT_NE(out.find(c.says), std::string::npos) << args << ": " << out;
    EXPECT_FALSE(fs::exists(target)) << args;
  }
  EXPECT_EQ(testing::runScanpress("merge '" + p0 + "' '" + p1 + "' '" + p2 + "' '" + p0 + "'", &out), 1);
  EXPECT_NE(out.find("refusing to overwrite"), std::string::npos) << out;
  // Options.
  for (const char* bad : {"--subset 3/3", "--subset 0/1", "--subset x", "--subset 0/2 --max-error 1e-4"}) {
    EXPECT_EQ(testing::runScanpress("encode '" + a + "' '" + dir_->file("z.spz") + "' " + bad, &out), 1) << bad;
    EXPECT_NE(out.find("--subset"), std::string::npos) << bad << ": " << out;
  }
  // A header claiming subset count 1 (CRC-valid) is malformed, at byte 72.
  auto bytes = testing::readBytes(p1);
  bytes[74] = 1, bytes[75] = 0, bytes[72] = 0, bytes[73] = 0;
  const uint32_t crc = crc32c(std::span<const uint8_t>(bytes.data(), 76));
  std::memcpy(bytes.data() + 76, &crc, 4);
  testing::writeBytes(dir_->file("bad.spz"), std::string(bytes.begin(), bytes.end()));
  auto bad = ContainerFile::open(dir_->file("bad.spz"));
  ASSERT_FALSE(bad.isOk());
  EXPECT_NE(bad.status().message().find("byte 72"), std::string::npos) << bad.status().toString();
}

}  // namespace
}  // namespace scanpress
