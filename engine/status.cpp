#include "engine/status.h"

namespace scanpress {

const char* errorCodeName(ErrorCode code) {
  switch (code) {
    case ErrorCode::kOk: return "ok";
    case ErrorCode::kInvalidArgument: return "invalid argument";
    case ErrorCode::kMalformed: return "malformed input";
    case ErrorCode::kTruncated: return "truncated input";
    case ErrorCode::kChecksum: return "checksum mismatch";
    case ErrorCode::kUnknownVersion: return "unknown version";
    case ErrorCode::kUnknownCodec: return "unknown codec";
    case ErrorCode::kUnsupported: return "unsupported input";
    case ErrorCode::kLimitExceeded: return "limit exceeded";
    case ErrorCode::kIo: return "I/O error";
    case ErrorCode::kDiskFull: return "disk full";
    case ErrorCode::kInternal: return "internal error";
  }
  return "unknown error";
}

int exitCodeFor(ErrorCode code) {
  switch (code) {
    case ErrorCode::kOk: return 0;
    case ErrorCode::kInvalidArgument: return 1;
    case ErrorCode::kMalformed:
    case ErrorCode::kTruncated:
    case ErrorCode::kChecksum:
    case ErrorCode::kUnknownVersion:
    case ErrorCode::kUnknownCodec:
    case ErrorCode::kUnsupported:
    case ErrorCode::kLimitExceeded: return 2;
    case ErrorCode::kIo:
    case ErrorCode::kDiskFull: return 3;
    case ErrorCode::kInternal: return 4;
  }
  return 4;
}

std::string Status::toString() const {
  if (isOk()) return "ok";
  return std::string(errorCodeName(code_)) + ": " + message_;
}

}  // namespace scanpress
