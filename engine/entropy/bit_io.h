// Raw bit packing (LSB-first within little-endian 64-bit words), for fixed-width fields such as the `store`
// codec's tightly packed coordinates and indices.
//
// BitReader never reads outside its span: reading past the end returns zero bits and sets `overrun()`.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

namespace scanpress {

class BitWriter {
 public:
  explicit BitWriter(std::vector<uint8_t>& out) : out_(out) {}
  // Writes the low `bits` bits of `value` (0 <= bits <= 32).
  void put(uint32_t value, int bits) {
    if (bits == 0) return;
    acc_ |= uint64_t(value & (bits == 32 ? 0xFFFFFFFFu : ((1u << bits) - 1))) << fill_;
    fill_ += bits;
    while (fill_ >= 8) {
      out_.push_back(static_cast<uint8_t>(acc_));
      acc_ >>= 8;
      fill_ -= 8;
    }
  }
  // Pads the last byte with zero bits.
  void flush() {
    if (fill_ > 0) out_.push_back(static_cast<uint8_t>(acc_));
    acc_ = 0;
    fill_ = 0;
  }

 private:
  std::vector<uint8_t>& out_;
  uint64_t acc_ = 0;
  int fill_ = 0;
};

class BitReader {
 public:
  explicit BitReader(std::span<const uint8_t> data) : data_(data) {}
  uint32_t get(int bits) {
    if (bits == 0) return 0;
    while (fill_ < bits) {
      uint64_t byte = 0;
      if (pos_ < data_.size()) byte = data_[pos_++];
      else overrun_ = true;
      acc_ |= byte << fill_;
      fill_ += 8;
    }
    const uint32_t v = static_cast<uint32_t>(acc_ & (bits == 32 ? 0xFFFFFFFFull : ((1ull << bits) - 1)));
    acc_ >>= bits;
    fill_ -= bits;
    return v;
  }
  bool overrun() const { return overrun_; }

 private:
  std::span<const uint8_t> data_;
  size_t pos_ = 0;
  uint64_t acc_ = 0;
  int fill_ = 0;
  bool overrun_ = false;
};

// Number of bits needed to store values 0..max_value (0 for max_value == 0).
inline int bitsFor(uint64_t max_value) {
  int b = 0;
  while (max_value >> b) ++b;
  return b;
}

}  // namespace scanpress
