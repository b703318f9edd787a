// Helpers of the jobs layer: the errno mapping and the number parser shared by the CLI and job files.
#include <gtest/gtest.h>

#include <cerrno>
#include <cstring>

#include "jobs/errors.h"
#include "jobs/file_io.h"
#include "jobs/numbers.h"
#include "jobs/scan_store.h"
#include "jobs_util.h"
#include "jobs/progress.h"
#include "test_util.h"

namespace scanpress {
namespace {

TEST(ErrnoStatus, NoSpaceIsDiskFullTheRestIsIoBothExitThree) {
  for (int err : {ENOSPC, EDQUOT, EFBIG}) EXPECT_EQ(errnoErrorCode(err), ErrorCode::kDiskFull) << err;
  for (int err : {ENOENT, EACCES, EPERM, EISDIR, ENOTDIR, EROFS, EIO, EMFILE, ENAMETOOLONG, EINVAL, 0})
    EXPECT_EQ(errnoErrorCode(err), ErrorCode::kIo) << err;
  EXPECT_EQ(exitCodeFor(ErrorCode::kDiskFull), 3);
  EXPECT_EQ(exitCodeFor(ErrorCode::kIo), 3);
  const Status s = errnoStatus(ENOSPC, "out/a.spz", "write failed");
  EXPECT_EQ(s.code(), ErrorCode::kDiskFull);
  EXPECT_EQ(s.message(), std::string("out/a.spz: write failed: ") + std::strerror(ENOSPC));
}

TEST(ErrnoStatus, FilesReportThroughIt) {
  testing::TempDir dir;
  auto missing = RandomAccessFile::open(dir.file("missing.spz"));
  ASSERT_FALSE(missing.isOk());
  EXPECT_EQ(missing.status().code(), ErrorCode::kIo);
  EXPECT_NE(missing.status().message().find(std::strerror(ENOENT)), std::string::npos) << missing.status().message();
  testing::writeBytes(dir.file("file"), "x");  // a missing folder is created, one under a file cannot be
  auto no_dir = AtomicFile::create(dir.file("file/dir/a.spz"));
  ASSERT_FALSE(no_dir.isOk());
  EXPECT_EQ(no_dir.status().code(), ErrorCode::kIo);
  // /dev/full fails every write with ENOSPC.
  ScratchFile full;
  if (!full.open("/dev/full").isOk()) GTEST_SKIP() << "no writable /dev/full";
  const char byte = 1;
  const Status w = full.writeAt(0, &byte, 1);
  EXPECT_EQ(w.code(), ErrorCode::kDiskFull) << w.toString();
  EXPECT_NE(w.message().find("/dev/full"), std::string::npos);
}

// The message of a failed parse ("" when it succeeded), checked to be a usage error.
template <typename T>
std::string error(const Result<T>& r) {
  if (r.isOk()) return "";
  EXPECT_EQ(r.status().code(), ErrorCode::kInvalidArgument);
  return r.status().message();
}

TEST(Numbers, IntegersInRange) {
  EXPECT_EQ(*parseInteger("16", 8, 24, "--bits"), 16);
  EXPECT_EQ(*parseInteger("+16", 8, 24, "--bits"), 16);
  EXPECT_EQ(*parseInteger("-5", -10, 10, "x"), -5);
  EXPECT_EQ(*parseInteger("0", 0, 0, "x"), 0);
  EXPECT_EQ(*parseInteger("-0", 0, 0, "x"), 0);
  // What users type for whole numbers: exponents, a zero fraction.
  EXPECT_EQ(*parseInteger("1e6", 0, INT64_MAX, "x"), 1000000);
  EXPECT_EQ(*parseInteger("2.5e3", 0, INT64_MAX, "x"), 2500);
  EXPECT_EQ(*parseInteger("16.0", 8, 24, "x"), 16);
  EXPECT_EQ(*parseInteger("1E+2", 0, 1000, "x"), 100);
  EXPECT_EQ(*parseInteger("12000e-3", 0, 1000, "x"), 12);
  EXPECT_EQ(*parseInteger("9223372036854775807", 0, INT64_MAX, "x"), INT64_MAX);
  EXPECT_EQ(*parseInteger("-9223372036854775808", INT64_MIN, 0, "x"), INT64_MIN);
  EXPECT_EQ(error(parseInteger("99", 8, 24, "--bits")), "--bits: must be an integer in [8, 24], got '99'");
  EXPECT_EQ(error(parseInteger("7", 8, 24, "/codec/bits")), "/codec/bits: must be an integer in [8, 24], got '7'");
  std::vector<std::string> bad = {"", " 16", "16 ", "1.5", "16x", "0x10", "1_000", "--16", "+-1", "1e", "e3"};
  bad.insert(bad.end(), {".5", "5.", "1.5e0", "nan", "inf", "-1", "1e19", "1e400", "99999999999999999999999"});
  bad.insert(bad.end(), {"9223372036854775808", "-9223372036854775809"});
  for (const auto& b : bad) EXPECT_NE(error(parseInteger(b, 0, INT64_MAX, "x")), "") << b;
}

TEST(Numbers, UnsignedFullRange) {
  EXPECT_EQ(*parseUnsigned("18446744073709551615", UINT64_MAX, "--seed"), UINT64_MAX);
  EXPECT_EQ(*parseUnsigned("1e19", UINT64_MAX, "--seed"), 10000000000000000000ull);
  EXPECT_EQ(*parseUnsigned("0", UINT64_MAX, "--seed"), 0u);
  EXPECT_EQ(*parseUnsigned("-0", UINT64_MAX, "--seed"), 0u);
  EXPECT_EQ(error(parseUnsigned("-1", UINT64_MAX, "--seed")),
            "--seed: must be a non-negative integer below 2^64, got '-1'");
  EXPECT_EQ(error(parseUnsigned("25", 24, "--level")), "--level: must be a non-negative integer in [0, 24], got '25'");
  for (const char* bad : {"18446744073709551616", "2e19", "1.5", "", "abc", " -1", "1e-3"})
    EXPECT_NE(error(parseUnsigned(bad, UINT64_MAX, "x")), "") << bad;
}

TEST(Numbers, DoublesFiniteInRange) {
  EXPECT_EQ(*parseNumber("2", 1e-6, 1e6, "x"), 2.0);
  EXPECT_EQ(*parseNumber("+0.5", 0, 1, "x"), 0.5);
  EXPECT_EQ(*parseNumber("-2.5e-1", -1, 1, "x"), -0.25);
  EXPECT_EQ(*parseNumber("1e6", 1e-6, 1e6, "x"), 1e6);
  EXPECT_EQ(error(parseNumber("0", 1e-6, 1e6, "--samples-per-triangle")),
            "--samples-per-triangle: must be a number in [1e-06, 1e+06], got '0'");
  for (const char* bad : {"", "1e400", "-1e400", "inf", "nan", "1,5", "2x", " 2", "+-2", "0x10", "1e6.5"})
    EXPECT_NE(error(parseNumber(bad, -1e300, 1e300, "x")), "") << bad;
}

TEST(Numbers, SizesWithBinaryUnits) {
  auto size = [](const char* text) { return *parseSize(text, "--memory-budget"); };
  EXPECT_EQ(size("512"), 512ull << 20);  // no unit: MiB
  EXPECT_EQ(size("0"), 0u);
  for (const char* k : {"64K", "64k", "64KB", "64kb", "64KiB", "64kib", "64Ki"}) EXPECT_EQ(size(k), 64ull << 10) << k;
  for (const char* m : {"512M", "512m", "512MB", "512MiB"}) EXPECT_EQ(size(m), 512ull << 20) << m;
  for (const char* g : {"2G", "2g", "2GB", "2GiB"}) EXPECT_EQ(size(g), 2ull << 30) << g;
  EXPECT_EQ(size("2T"), 2ull << 40);
  EXPECT_EQ(size("100B"), 100u);
  EXPECT_EQ(size("1.5G"), 3ull << 29);
  EXPECT_EQ(size("0.5K"), 512u);
  EXPECT_EQ(size("1.0001K"), 1024u);  // rounds down to whole bytes
  EXPECT_EQ(size("16777215T"), 16777215ull << 40);
  EXPECT_NE(error(parseSize("16777216T", "x")), "");  // 2^64 bytes
  EXPECT_NE(error(parseSize("99999999999999999999", "x")), "");
  const std::string message = error(parseSize("2X", "--memory-budget"));
  EXPECT_EQ(message.find("--memory-budget: must be a size"), 0u) << message;
  EXPECT_NE(message.find("got '2X'"), std::string::npos) << message;
  for (const char* bad :
       {"", "-1", "-1G", "G", "1.G", ".5G", "1..5G", "1e3", "1GG", "1Gi B", " 1G", "1 G", "1KiBB", "1iB"})
    EXPECT_NE(error(parseSize(bad, "x")), "") << bad;
}

TEST(Numbers, Lists) {
  EXPECT_EQ(*parseIntegerList("1,2,3", 0, UINT32_MAX, 0, "--tiles"), (std::vector<int64_t>{1, 2, 3}));
  EXPECT_EQ(*parseIntegerList("7", 0, UINT32_MAX, 0, "--tiles"), (std::vector<int64_t>{7}));
  EXPECT_EQ(*parseIntegerList("800,600", 16, 8192, 2, "--size"), (std::vector<int64_t>{800, 600}));
  EXPECT_EQ(*parseNumberList("30,-20.5", -360, 360, 2, "--view"), (std::vector<double>{30, -20.5}));
  EXPECT_EQ(error(parseIntegerList("1,x", 0, UINT32_MAX, 0, "--tiles")),
            "--tiles: must be an integer in [0, 4294967295], got 'x'");
  EXPECT_EQ(error(parseIntegerList("800", 16, 8192, 2, "--size")),
            "--size: must be 2 values separated by commas, got '800'");
  for (const char* bad : {"", "1,", ",1", "1,,2", "1 ,2", "4294967296", "-1"})
    EXPECT_NE(error(parseIntegerList(bad, 0, UINT32_MAX, 0, "x")), "") << bad;
  EXPECT_NE(error(parseNumberList("1,2,3", -360, 360, 2, "x")), "");
  EXPECT_NE(error(parseNumberList("400,0", -360, 360, 2, "x")), "");
}

}  // namespace
}  // namespace scanpress

namespace scanpress {
namespace {

// Off a terminal (a batch log), progress is a plain line per interval with tiles, Mtri/s and an ETA; never the
// terminal's carriage returns; nothing when quiet.
TEST(Progress, LogLinesOffATerminal) {
  auto text = [](bool quiet) {
    FILE* f = std::tmpfile();
    {
      TerminalProgress p(quiet, f, /*terminal=*/false, /*log_interval=*/0);
      p.file(1, 3, "scan.ply");
      p.stage("encode");
      p.tiles(1, 4, 1000);
      p.tiles(4, 4, 4000);
    }
    std::rewind(f);
    std::string s;
    for (int c; (c = std::fgetc(f)) != EOF;) s += static_cast<char>(c);
    std::fclose(f);
    return s;
  };
  const std::string log = text(false);
  EXPECT_NE(log.find("[2/3] scan.ply: encode, tiles 1/4, "), std::string::npos) << log;
  EXPECT_NE(log.find(", ETA "), std::string::npos) << log;
  EXPECT_NE(log.find("tiles 4/4"), std::string::npos) << log;
  EXPECT_EQ(log.find('\r'), std::string::npos) << log;
  EXPECT_EQ(text(true), "");
}

}  // namespace
}  // namespace scanpress
