#include "jobs/errors.h"

#include <cerrno>
#include <cstring>
#include <exception>
#include <new>

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

Status statusFromException() {
  try {
    throw;
  } catch (const std::bad_alloc&) {
    return makeError(ErrorCode::kIo, "out of memory");
  } catch (const std::exception& e) {
    return makeError(ErrorCode::kInternal, e.what());
  } catch (...) {
    return makeError(ErrorCode::kInternal, "unknown exception");
  }
}

}  // namespace scanpress
