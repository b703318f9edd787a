// Little-endian byte writer and a bounds-checked byte reader for format code (container, codec headers).
//
// ByteReader never reads outside its span: a read past the end fails with kTruncated and names the offset
// (relative to `base_offset`, so errors can be reported as absolute file offsets).
#pragma once

#include <cstdint>
#include <cstring>
#include <span>
#include <string>
#include <vector>

#include "engine/status.h"

namespace scanpress {

class ByteWriter {
 public:
  explicit ByteWriter(std::vector<uint8_t>& out) : out_(out) {}
  void u8(uint8_t v) { out_.push_back(v); }
  void u16(uint16_t v) { putLe(v, 2); }
  void u32(uint32_t v) { putLe(v, 4); }
  void u64(uint64_t v) { putLe(v, 8); }
  void f64(double v) {
    uint64_t bits;
    std::memcpy(&bits, &v, 8);
    u64(bits);
  }
  // LEB128: 7 bits per byte, low bits first, high bit set on every byte but the last.
  void varint(uint64_t v) {
    while (v >= 0x80) {
      out_.push_back(static_cast<uint8_t>(v | 0x80));
      v >>= 7;
    }
    out_.push_back(static_cast<uint8_t>(v));
  }
  void bytes(std::span<const uint8_t> data) { out_.insert(out_.end(), data.begin(), data.end()); }
  size_t size() const { return out_.size(); }

 private:
  void putLe(uint64_t v, int n) {
    for (int i = 0; i < n; ++i) out_.push_back(static_cast<uint8_t>(v >> (8 * i)));
  }
  std::vector<uint8_t>& out_;
};

class ByteReader {
 public:
  ByteReader(std::span<const uint8_t> data, std::string what, uint64_t base_offset = 0)
      : data_(data), what_(std::move(what)), base_(base_offset) {}

  Status u8(uint8_t& v) { return getLe(v); }
  Status u16(uint16_t& v) { return getLe(v); }
  Status u32(uint32_t& v) { return getLe(v); }
  Status u64(uint64_t& v) { return getLe(v); }
  Status f64(double& v) {
    uint64_t bits = 0;
    SP_RETURN_IF_ERROR(u64(bits));
    std::memcpy(&v, &bits, 8);
    return Status::ok();
  }
  // LEB128 of at most 10 bytes whose value fits 64 bits; anything else is kMalformed.
  Status varint(uint64_t& v) {
    v = 0;
    for (int shift = 0; shift < 64; shift += 7) {
      uint8_t b = 0;
      SP_RETURN_IF_ERROR(u8(b));
      if (shift == 63 && b > 1) return error(ErrorCode::kMalformed, "varint overflows 64 bits");
      v |= uint64_t(b & 0x7F) << shift;
      if (!(b & 0x80)) return Status::ok();
    }
    return error(ErrorCode::kMalformed, "varint longer than 10 bytes");
  }
  Status bytes(size_t n, std::span<const uint8_t>& out) {
    SP_RETURN_IF_ERROR(need(n));
    out = data_.subspan(pos_, n);
    pos_ += n;
    return Status::ok();
  }
  size_t position() const { return pos_; }
  size_t remaining() const { return data_.size() - pos_; }
  uint64_t absoluteOffset() const { return base_ + pos_; }
  // An error of the given code that names this reader's subject and the current absolute offset.
  Status error(ErrorCode code, const std::string& message) const {
    return Status(code, what_ + " at byte " + std::to_string(absoluteOffset()) + ": " + message);
  }

 private:
  Status need(size_t n) const {
    if (n > remaining())
      return error(ErrorCode::kTruncated,
                   "needs " + std::to_string(n) + " more bytes, " + std::to_string(remaining()) + " left");
    return Status::ok();
  }
  template <typename T>
  Status getLe(T& v) {
    SP_RETURN_IF_ERROR(need(sizeof(T)));
    uint64_t r = 0;
    for (size_t i = 0; i < sizeof(T); ++i) r |= uint64_t(data_[pos_ + i]) << (8 * i);
    v = static_cast<T>(r);
    pos_ += sizeof(T);
    return Status::ok();
  }

  std::span<const uint8_t> data_;
  std::string what_;
  uint64_t base_;
  size_t pos_ = 0;
};

}  // namespace scanpress
