// Helpers of the jobs layer: the errno mapping and the number parser shared by the CLI and job files.
#include <gtest/gtest.h>

#include <cerrno>
#include <cstring>

#include "jobs/errors.h"
#include "jobs/file_io.h"
#include "jobs/scan_store.h"
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
  auto no_dir = AtomicFile::create(dir.file("no/such/dir/a.spz"));
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

}  // namespace
}  // namespace scanpress
