// Byte input for mesh readers: plain files and zstd-compressed files (detected by their magic, not the name),
// behind one buffered Scanner that tracks the byte offset and the line number for error messages.
#pragma once

#include <cstdint>
#include <cstring>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "engine/status.h"

namespace scanpress {

class InputSource {
 public:
  virtual ~InputSource() = default;
  // Reads up to `n` bytes into `dst`; 0 means end of input.
  virtual Result<size_t> read(uint8_t* dst, size_t n) = 0;
  // Size of the (decompressed) content when known in advance.
  virtual std::optional<uint64_t> contentSize() const = 0;
  virtual bool compressed() const = 0;

  // Opens `path`; zstd frames are decompressed on the fly.
  static Result<std::unique_ptr<InputSource>> open(const std::string& path);
};

class Scanner {
 public:
  Scanner(std::unique_ptr<InputSource> source, std::string name);

  const std::string& name() const { return name_; }
  uint64_t offset() const { return consumed_ + pos_; }
  uint64_t line() const { return line_; }
  std::optional<uint64_t> contentSize() const { return source_->contentSize(); }
  bool compressedInput() const { return source_->compressed(); }
  // Bytes left when the size is known in advance.
  std::optional<uint64_t> remaining() const {
    auto s = contentSize();
    if (!s) return std::nullopt;
    return *s > offset() ? *s - offset() : 0;
  }

  // Errors that name the file and the place.
  Status errorAtOffset(ErrorCode code, const std::string& message) const;
  Status errorAtLine(ErrorCode code, const std::string& message) const;

  // Binary: reads exactly `n` bytes or fails with kTruncated.
  Status read(void* dst, size_t n) {
    if (n == 0) return Status::ok();  // dst may be an empty vector's null data(): memcpy must not see it
    if (end_ - pos_ >= n) {
      std::memcpy(dst, buf_.data() + pos_, n);
      pos_ += n;
      return Status::ok();
    }
    return readSlow(static_cast<uint8_t*>(dst), n);
  }
  // Up to `n` bytes from the current position without consuming them (fewer at end of input).
  Result<std::span<const uint8_t>> peek(size_t n);

  // Text: the next line without its terminator ("\n", "\r\n" or "\r"); false at end of input. Lines longer
  // than kMaxLine are an error.
  Result<bool> nextLine(std::string_view& line);
  static constexpr size_t kMaxLine = 16u << 20;
  // After a text header that ended in "\r": drops the '\n' of a "\r\n" before binary data starts.
  Status consumePendingLineFeed();

 private:
  Status readSlow(uint8_t* dst, size_t n);
  Status lineTooLong() const;
  Result<bool> fill();  // makes more bytes available; false at end of input

  std::unique_ptr<InputSource> source_;
  std::string name_;
  std::vector<uint8_t> buf_;
  size_t pos_ = 0, end_ = 0;
  uint64_t consumed_ = 0;  // bytes dropped from the front of buf_ so far
  uint64_t line_ = 0;      // number of the line last returned by nextLine (1-based)
  bool eof_ = false;
  bool skip_lf_ = false;  // the previous line ended in '\r': a following '\n' belongs to it
};

// Splits a text line into whitespace-separated tokens.
class Tokenizer {
 public:
  explicit Tokenizer(std::string_view s) : s_(s) {}
  bool next(std::string_view& token) {
    while (i_ < s_.size() && (s_[i_] == ' ' || s_[i_] == '\t' || s_[i_] == '\f' || s_[i_] == '\v')) ++i_;
    if (i_ >= s_.size()) return false;
    const size_t start = i_;
    while (i_ < s_.size() && !(s_[i_] == ' ' || s_[i_] == '\t' || s_[i_] == '\f' || s_[i_] == '\v')) ++i_;
    token = s_.substr(start, i_ - start);
    return true;
  }
  std::string_view rest() const { return i_ < s_.size() ? s_.substr(i_) : std::string_view(); }

 private:
  std::string_view s_;
  size_t i_ = 0;
};

bool parseDouble(std::string_view token, double& value);
bool parseInt64(std::string_view token, int64_t& value);

}  // namespace scanpress
