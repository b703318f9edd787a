#include "jobs/mesh_io/input.h"

#include <zstd.h>

#include <algorithm>
#include <cerrno>
#include <charconv>
#include <cstdio>
#include <system_error>

#include "jobs/errors.h"

namespace scanpress {
namespace {

class FileSource : public InputSource {
 public:
  FileSource(FILE* f, std::string path, std::optional<uint64_t> size) : f_(f), path_(std::move(path)), size_(size) {}
  ~FileSource() override { std::fclose(f_); }
  Result<size_t> read(uint8_t* dst, size_t n) override {
    const size_t got = std::fread(dst, 1, n, f_);
    if (got < n && std::ferror(f_)) return errnoStatus(errno, path_, "read failed");
    return got;
  }
  std::optional<uint64_t> contentSize() const override { return size_; }
  bool compressed() const override { return false; }

 private:
  FILE* f_;
  std::string path_;
  std::optional<uint64_t> size_;
};

class ZstdSource : public InputSource {
 public:
  ZstdSource(std::unique_ptr<FileSource> file, std::string path, std::optional<uint64_t> size)
      : file_(std::move(file)), path_(std::move(path)), size_(size), in_buf_(ZSTD_DStreamInSize()) {
    dctx_ = ZSTD_createDCtx();
    // Bound the window a hostile frame may demand (2^27 = 128 MiB; zstd -19 uses at most 8 MiB).
    ZSTD_DCtx_setParameter(dctx_, ZSTD_d_windowLogMax, 27);
  }
  ~ZstdSource() override { ZSTD_freeDCtx(dctx_); }

  Result<size_t> read(uint8_t* dst, size_t n) override {
    ZSTD_outBuffer out{dst, n, 0};
    while (out.pos == 0) {
      if (in_.pos == in_.size) {
        if (in_eof_) {
          if (!frame_done_)
            return makeError(ErrorCode::kTruncated, path_ + ": byte " + std::to_string(compressed_offset_) +
                                                        " of the compressed file: zstd stream ends inside a frame "
                                                        "(compressed file truncated)");
          return size_t{0};
        }
        SP_ASSIGN_OR_RETURN(size_t got, file_->read(in_buf_.data(), in_buf_.size()));
        compressed_offset_ += in_.size;
        in_ = ZSTD_inBuffer{in_buf_.data(), got, 0};
        if (got == 0) {
          in_eof_ = true;
          continue;
        }
      }
      const size_t ret = ZSTD_decompressStream(dctx_, &out, &in_);
      if (ZSTD_isError(ret))
        return makeError(ErrorCode::kMalformed, path_ + ": zstd data corrupt near compressed byte " +
                                                    std::to_string(compressed_offset_ + in_.pos) + ": " +
                                                    ZSTD_getErrorName(ret));
      frame_done_ = (ret == 0);
    }
    return out.pos;
  }
  std::optional<uint64_t> contentSize() const override { return size_; }
  bool compressed() const override { return true; }

 private:
  std::unique_ptr<FileSource> file_;
  std::string path_;
  std::optional<uint64_t> size_;
  std::vector<uint8_t> in_buf_;
  ZSTD_inBuffer in_{nullptr, 0, 0};
  ZSTD_DCtx* dctx_ = nullptr;
  uint64_t compressed_offset_ = 0;
  bool in_eof_ = false;
  bool frame_done_ = true;
};

}  // namespace

Result<std::unique_ptr<InputSource>> InputSource::open(const std::string& path) {
  FILE* f = std::fopen(path.c_str(), "rb");
  if (!f) return errnoStatus(errno, path, "cannot open");
  std::optional<uint64_t> size;
  if (std::fseek(f, 0, SEEK_END) == 0) {
    const long s = std::ftell(f);
    if (s >= 0) size = static_cast<uint64_t>(s);
    std::fseek(f, 0, SEEK_SET);
  }
  uint8_t magic[18] = {};
  const size_t got = std::fread(magic, 1, sizeof magic, f);
  std::fseek(f, 0, SEEK_SET);
  auto file = std::make_unique<FileSource>(f, path, size);
  if (got >= 4 && magic[0] == 0x28 && magic[1] == 0xB5 && magic[2] == 0x2F && magic[3] == 0xFD) {
    std::optional<uint64_t> content;
    const unsigned long long cs = ZSTD_getFrameContentSize(magic, got);
    if (cs != ZSTD_CONTENTSIZE_UNKNOWN && cs != ZSTD_CONTENTSIZE_ERROR) content = cs;
    return std::unique_ptr<InputSource>(std::make_unique<ZstdSource>(std::move(file), path, content));
  }
  return std::unique_ptr<InputSource>(std::move(file));
}

Scanner::Scanner(std::unique_ptr<InputSource> source, std::string name)
    : source_(std::move(source)), name_(std::move(name)), buf_(1u << 20) {}

Status Scanner::errorAtOffset(ErrorCode code, const std::string& message) const {
  return makeError(code, name_ + ": byte " + std::to_string(offset()) +
                             (source_->compressed() ? " of the decompressed data" : "") + ": " + message);
}

Status Scanner::errorAtLine(ErrorCode code, const std::string& message) const {
  return makeError(code, name_ + ":" + std::to_string(std::max<uint64_t>(line_, 1)) + ": " + message);
}

// The line being read is the one after the last returned; the limit applies to every line, the last one (with no
// terminator) included, whatever the buffer happened to hold.
Status Scanner::lineTooLong() const {
  return makeError(ErrorCode::kLimitExceeded, name_ + ":" + std::to_string(line_ + 1) + ": line longer than " +
                                                  std::to_string(kMaxLine >> 20) + " MiB (the limit for text formats)");
}

Result<bool> Scanner::fill() {
  if (eof_) return false;
  if (pos_ > 0) {  // move the unread tail to the front
    std::memmove(buf_.data(), buf_.data() + pos_, end_ - pos_);
    consumed_ += pos_;
    end_ -= pos_;
    pos_ = 0;
  }
  if (end_ == buf_.size()) {
    if (buf_.size() >= kMaxLine + 16) return errorAtOffset(ErrorCode::kLimitExceeded, "line too long");
    buf_.resize(buf_.size() * 2);
  }
  SP_ASSIGN_OR_RETURN(size_t got, source_->read(buf_.data() + end_, buf_.size() - end_));
  if (got == 0) {
    eof_ = true;
    return false;
  }
  end_ += got;
  return true;
}

Status Scanner::readSlow(uint8_t* dst, size_t n) {
  while (n > 0) {
    if (pos_ == end_) {
      SP_ASSIGN_OR_RETURN(bool more, fill());
      if (!more) return errorAtOffset(ErrorCode::kTruncated, "unexpected end of file");
    }
    const size_t k = std::min(n, end_ - pos_);
    std::memcpy(dst, buf_.data() + pos_, k);
    pos_ += k;
    dst += k;
    n -= k;
  }
  return Status::ok();
}

Result<std::span<const uint8_t>> Scanner::peek(size_t n) {
  while (end_ - pos_ < n) {
    SP_ASSIGN_OR_RETURN(bool more, fill());
    if (!more) break;
  }
  return std::span<const uint8_t>(buf_.data() + pos_, std::min(n, end_ - pos_));
}

Result<bool> Scanner::nextLine(std::string_view& line) {
  size_t scan = pos_;
  for (;;) {
    if (skip_lf_ && pos_ < end_) {
      if (buf_[pos_] == '\n') ++pos_;
      skip_lf_ = false;
      scan = pos_;
    }
    const void* hit = nullptr;
    size_t i = scan;
    for (; i < end_; ++i)
      if (buf_[i] == '\n' || buf_[i] == '\r') {
        hit = &buf_[i];
        break;
      }
    if (hit) {
      if (i - pos_ > kMaxLine) return lineTooLong();
      line = std::string_view(reinterpret_cast<const char*>(buf_.data() + pos_), i - pos_);
      if (buf_[i] == '\r') skip_lf_ = true;
      pos_ = i + 1;
      ++line_;
      return true;
    }
    const size_t scanned = end_ - pos_;
    if (scanned > kMaxLine) return lineTooLong();
    SP_ASSIGN_OR_RETURN(bool more, fill());
    scan = pos_ + scanned;
    if (!more) {
      if (pos_ == end_) return false;
      if (end_ - pos_ > kMaxLine) return lineTooLong();
      line = std::string_view(reinterpret_cast<const char*>(buf_.data() + pos_), end_ - pos_);
      pos_ = end_;
      ++line_;
      return true;
    }
  }
}

Status Scanner::consumePendingLineFeed() {
  if (!skip_lf_) return Status::ok();
  skip_lf_ = false;
  SP_ASSIGN_OR_RETURN(auto head, peek(1));
  if (!head.empty() && head[0] == '\n') ++pos_;
  return Status::ok();
}

namespace {

// std::from_chars over the whole token (a leading '+' allowed, as C's strtod and the mesh formats allow).
template <typename T>
bool parseWhole(std::string_view token, T& value) {
  const char* b = token.data();
  const char* e = b + token.size();
  if (b != e && *b == '+') ++b;
  auto [ptr, ec] = std::from_chars(b, e, value);
  return ec == std::errc() && ptr == e;
}

}  // namespace

bool parseDouble(std::string_view token, double& value) { return parseWhole(token, value); }
bool parseInt64(std::string_view token, int64_t& value) { return parseWhole(token, value); }

}  // namespace scanpress
