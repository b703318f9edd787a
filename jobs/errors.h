// System errors as Status: the one mapping of errno for every file the jobs layer opens, reads or writes.
//
// ENOSPC, EDQUOT and EFBIG (no space left, quota exceeded, file too large) are kDiskFull; every other errno
// (ENOENT, EACCES, EISDIR, EROFS, EIO, EMFILE, ...) is kIo. Both mean exit code 3: the environment failed,
// not the usage (1) nor the input data (2). The message is `PATH: WHAT: strerror(err)`.
#pragma once

#include <string>
#include <string_view>

#include "engine/status.h"

namespace scanpress {

ErrorCode errnoErrorCode(int err);

// Pass errno as read right after the failing call (later calls may overwrite it).
Status errnoStatus(int err, const std::string& path, std::string_view what);

// The exception being handled (call it inside a catch block) as a Status, so that it stops at a task or file
// boundary: std::bad_alloc is kIo ("out of memory": the environment), anything else kInternal.
Status statusFromException();

}  // namespace scanpress
