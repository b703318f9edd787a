// Status and Result<T>: the error type of every fallible engine, spatial and jobs function.
//
// Error codes are stable (they are printed, mapped to exit codes and may be stored in reports). Add new ones at the
// end; never renumber. A Status carries a human-readable message that names the place of the problem (file,
// line, byte offset, tile, JSON pointer); callers add context with Status::withContext.
#pragma once

#include <cstdint>
#include <string>
#include <utility>
#include <variant>

namespace scanpress {

enum class ErrorCode : uint8_t {
  kOk = 0,
  kInvalidArgument = 1,  // usage or configuration error (exit 1)
  kMalformed = 2,        // input bytes do not follow their format (exit 2)
  kTruncated = 3,        // input ends early (exit 2)
  kChecksum = 4,         // stored checksum does not match (exit 2)
  kUnknownVersion = 5,   // a format version this build does not know (exit 2)
  kUnknownCodec = 6,     // a codec id this build does not know (exit 2)
  kUnsupported = 7,      // well-formed input using a feature scanpress does not support (exit 2)
  kLimitExceeded = 8,    // input exceeds a documented limit, e.g. more than 2^32-1 vertices (exit 2)
  kIo = 9,               // the environment failed: open, read, write, rename (exit 3)
  kDiskFull = 10,        // ENOSPC / EDQUOT while writing (exit 3)
  kInternal = 11,        // a bug in scanpress (exit 4)
};

const char* errorCodeName(ErrorCode code);

// Process exit code for an error: 0 ok, 1 usage/config, 2 bad input data, 3 environment, 4 internal.
int exitCodeFor(ErrorCode code);

class [[nodiscard]] Status {
 public:
  Status() = default;
  Status(ErrorCode code, std::string message) : code_(code), message_(std::move(message)) {}

  static Status ok() { return Status(); }
  bool isOk() const { return code_ == ErrorCode::kOk; }
  ErrorCode code() const { return code_; }
  const std::string& message() const { return message_; }

  // Prefixes the message with `context: ` (e.g. a file name); ok statuses pass through unchanged.
  Status withContext(const std::string& context) const {
    if (isOk()) return *this;
    return Status(code_, context + ": " + message_);
  }
  std::string toString() const;

 private:
  ErrorCode code_ = ErrorCode::kOk;
  std::string message_;
};

inline Status makeError(ErrorCode code, std::string message) { return Status(code, std::move(message)); }

template <typename T>
class [[nodiscard]] Result {
 public:
  Result(T value) : data_(std::move(value)) {}         // NOLINT(google-explicit-constructor)
  Result(Status status) : data_(std::move(status)) {}  // NOLINT(google-explicit-constructor)

  bool isOk() const { return std::holds_alternative<T>(data_); }
  const Status& status() const {
    static const Status kOkStatus;
    return isOk() ? kOkStatus : std::get<Status>(data_);
  }
  T& value() & { return std::get<T>(data_); }
  const T& value() const& { return std::get<T>(data_); }
  T&& value() && { return std::get<T>(std::move(data_)); }
  T* operator->() { return &value(); }
  const T* operator->() const { return &value(); }
  T& operator*() & { return value(); }
  const T& operator*() const& { return value(); }
  T&& operator*() && { return std::move(*this).value(); }

 private:
  std::variant<T, Status> data_;
};

}  // namespace scanpress

#define SP_CONCAT_INNER(a, b) a##b
#define SP_CONCAT(a, b) SP_CONCAT_INNER(a, b)

#define SP_RETURN_IF_ERROR(expr)               \
  do {                                         \
    ::scanpress::Status sp_status_ = (expr);   \
    if (!sp_status_.isOk()) return sp_status_; \
  } while (0)

#define SP_ASSIGN_OR_RETURN_IMPL(tmp, lhs, expr) \
  auto tmp = (expr);                             \
  if (!tmp.isOk()) return tmp.status();          \
  lhs = std::move(tmp).value()

#define SP_ASSIGN_OR_RETURN(lhs, expr) SP_ASSIGN_OR_RETURN_IMPL(SP_CONCAT(sp_result_, __LINE__), lhs, expr)
