// A sample of the malformation sweep (test_malformation_sweep.cpp) through the CLI: a few mutations of every
// family and container written to files and decoded by `scanpress decode`, whose exit code must be 0 (ok) or
// 2 (a data error), never a signal, an internal error (4) or anything else.
#include <gtest/gtest.h>

#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <map>
#include <string>

#include "jobs_util.h"
#include "sweep_util.h"

namespace scanpress {
namespace {

namespace fs = std::filesystem;

// Two per family and container: 270 process starts (at four, the test took 28 of CI's seconds; the in-process sweep
// runs the same decoders on all the mutations). Release only: scripts/test.sh leaves it out under the sanitizers.
constexpr uint64_t kPerFamily = 2;

TEST(MalformationSweepCli, DecodeExitsWithZeroOrTwo) {
  const fs::path dir = fs::path(::testing::TempDir()) / ("sweep-cli-" + std::to_string(getpid()));
  fs::create_directories(dir);
  const std::string file = (dir / "m.spz").string(), out = (dir / "m.ply").string();
  std::map<int, uint64_t> exits;
  uint64_t runs = 0, seed = 1800;
  for (const sweep::SweepContainer& c : sweep::sweepContainers()) {
    for (const sweep::Family family : sweep::kFamilies) {
      ++seed;
      uint64_t count = 0;
      sweep::forEachMutation(c.bytes, family, seed, 200, [&](const std::vector<uint8_t>&) { ++count; });
      // Evenly spaced mutations of the family, from one generation of it.
      uint64_t i = 0, next = 0, taken = 0;
      sweep::forEachMutation(c.bytes, family, seed, 200, [&](const std::vector<uint8_t>& bytes) {
        if (i++ != next || taken == kPerFamily) return;
        ++taken;
        next = taken * count / kPerFamily;
        std::ofstream(file, std::ios::binary)
            .write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
        std::string text;
        const int code = testing::runScanpress("decode '" + file + "' '" + out + "' --quiet", &text);
        ++exits[code];
        ++runs;
        EXPECT_TRUE(code == 0 || code == 2) << c.name << ", " << sweep::familyName(family) << ", mutation #" << (i - 1)
                                            << ": exit " << code << ": " << text;
        if (sweep::mustBeRefused(family)) {
          EXPECT_EQ(code, 2) << c.name << ", " << sweep::familyName(family);
        }
        // A refusal names the file and the place: a byte offset or a tile.
        if (code == 2) {
          EXPECT_NE(text.find(file), std::string::npos) << text;
          EXPECT_TRUE(text.find("byte ") != std::string::npos || text.find("tile ") != std::string::npos)
              << c.name << ", " << sweep::familyName(family) << ": " << text;
        }
      });
    }
  }
  std::printf("CLI decode of %llu malformed containers: exit codes", static_cast<unsigned long long>(runs));
  for (const auto& [code, n] : exits) std::printf(" %d: %llu;", code, static_cast<unsigned long long>(n));
  std::printf("\n");
  EXPECT_GE(runs, 100u);
  fs::remove_all(dir);
}

}  // namespace
}  // namespace scanpress
