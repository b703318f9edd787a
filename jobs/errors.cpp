#include "jobs/errors.h"

#include <cerrno>
#include <cstring>

namespace scanpress {

ErrorCode errnoErrorCode(int err) {
  return (err == ENOSPC || err == EDQUOT || err == EFBIG) ? ErrorCode::kDiskFull : ErrorCode::kIo;
}

Status errnoStatus(int err, const std::string& path, std::string_view what) {
  std::string message = path;
  message += ": ";
  message += what;
  message += ": ";
  message += std::strerror(err);
  return makeError(errnoErrorCode(err), std::move(message));
}

}  // namespace scanpress
