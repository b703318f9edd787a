// Range coder with adaptive binary context models and adaptive multi-symbol models.
//
// One coder core serves both kinds of model, so a codec can interleave context-modelled bits, multi-symbol
// alphabets, explicitly given distributions (e.g. the kd-tree's "how many of p points fall in the left half") and
// raw bits in one stream.
//
// Core: a 32-bit range coder with LZMA's carry handling (64-bit low, cached byte + run of 0xFF bytes). The first
// byte LZMA emits is always zero and is not stored; the flush writes 4 bytes. Binary models keep two probability
// estimates with different adaptation rates (shift 5 and 7, the pair that did well on every kind of source:
// bench/RESULTS.md) and code with their mean: quick to follow drifting statistics, precise once they settle.
// Multi-symbol models follow A. Said, "Introduction to arithmetic coding" (2004) / FastAC: counts are updated
// per symbol, but the coding distribution (scaled to 2^15) is rebuilt only every `update_cycle` symbols, with a
// cycle that grows as the model settles; this makes encoding a multiply-and-shift and decoding a table lookup
// plus one division.
//
// Hostile input: RangeDecoder never reads outside its span. Reading past the end yields zero bytes and sets
// `overrun()`; decoded values are always in range for the model, so callers bound their loops by counts they
// validated and check `overrun()` before trusting the result.
//
// Thread safety: none; one coder and its models per thread.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

namespace scanpress {

// Adaptive binary model: probability that the next bit is 0, in 1/65536 units, as the mean of two estimators.
struct BitModel {
  uint16_t fast = 1u << 15;
  uint16_t slow = 1u << 15;
  uint32_t p0() const { return (uint32_t(fast) + slow) >> 1; }
  void update(int bit) {
    if (bit) {
      fast -= fast >> 5;
      slow -= slow >> 7;
    } else {
      fast += (65536 - fast) >> 5;
      slow += (65536 - slow) >> 7;
    }
  }
};

// Adaptive model over symbols 0..n-1 (1 <= n <= kMaxSymbols).
class SymbolModel {
 public:
  static constexpr uint32_t kMaxSymbols = 1u << 12;
  static constexpr uint32_t kTotalBits = 15;

  explicit SymbolModel(uint32_t num_symbols);
  uint32_t size() const { return n_; }

 private:
  friend class RangeEncoder;
  friend class RangeDecoder;
  void record(uint32_t symbol) {
    counts_[symbol] += kIncrement;
    total_ += kIncrement;
    if (--until_update_ == 0) rebuild();
  }
  void rebuild();
  uint32_t findSymbol(uint32_t value) const;  // symbol s with cum[s] <= value < cum[s+1]

  static constexpr uint32_t kIncrement = 32;
  static constexpr uint32_t kMaxTotal = 1u << 16;
  static constexpr uint32_t kLookupBits = 7;
  uint32_t n_;
  uint32_t total_ = 0;
  uint32_t update_cycle_;
  uint32_t until_update_;
  std::vector<uint32_t> counts_;
  std::vector<uint32_t> cum_;     // n+1 entries, cum_[n] == 1 << kTotalBits
  std::vector<uint16_t> lookup_;  // first symbol whose interval may contain value >> (kTotalBits - kLookupBits)
};

class RangeEncoder {
 public:
  // Appends the coded bytes to `out` (which may already hold data).
  explicit RangeEncoder(std::vector<uint8_t>& out) : out_(out) {}

  void encodeBit(BitModel& model, int bit);
  void encodeSymbol(SymbolModel& model, uint32_t symbol);
  // Codes `symbol` with interval [cum, cum+freq) out of `total` (1 <= freq, cum+freq <= total <= 2^16).
  void encodeFrequency(uint32_t cum, uint32_t freq, uint32_t total);
  // Codes `value` (< 2^bits, bits <= 32) with equal probabilities.
  void encodeBits(uint32_t value, int bits);
  // Codes `value` uniformly among `count` values (value < count); counts above 2^16 use whole bits.
  void encodeUniform(uint32_t value, uint32_t count);
  // Flushes the coder; no more symbols may be coded afterwards.
  void finish();
  // While set, every coded symbol adds its ideal cost (-log2 of its probability, in bits) to *meter: how codecs
  // report what each part of a stream costs. Off (nullptr) by default; costs one log2 per symbol when on.
  void setCostMeter(double* meter) { meter_ = meter; }

 private:
  void shiftLow();
  void normalize() {
    while (range_ < (1u << 24)) {
      range_ <<= 8;
      shiftLow();
    }
  }
  std::vector<uint8_t>& out_;
  uint64_t low_ = 0;
  uint32_t range_ = 0xFFFFFFFFu;
  uint8_t cache_ = 0;
  uint64_t pending_ = 1;  // cached byte plus pending 0xFF bytes
  bool first_ = true;     // LZMA's first output byte is always 0 and is dropped
  double* meter_ = nullptr;
};

class RangeDecoder {
 public:
  explicit RangeDecoder(std::span<const uint8_t> data);

  int decodeBit(BitModel& model);
  uint32_t decodeSymbol(SymbolModel& model);
  // Returns the value v in [0, total) locating the next symbol; the caller maps it to (cum, freq) and calls
  // consumeFrequency. Always < total, even on corrupt input.
  uint32_t peekFrequency(uint32_t total);
  void consumeFrequency(uint32_t cum, uint32_t freq);
  uint32_t decodeBits(int bits);
  uint32_t decodeUniform(uint32_t count);

  // True once the decoder needed bytes beyond the end of its input: the stream is truncated or corrupt.
  bool overrun() const { return overrun_; }
  // Bytes consumed so far (may exceed the input size by the bytes that were missing).
  size_t consumed() const { return consumed_; }

 private:
  uint8_t nextByte() {
    ++consumed_;
    if (pos_ < data_.size()) return data_[pos_++];
    overrun_ = true;
    return 0;
  }
  void normalize() {
    while (range_ < (1u << 24)) {
      range_ <<= 8;
      code_ = (code_ << 8) | nextByte();
    }
  }
  std::span<const uint8_t> data_;
  size_t pos_ = 0;
  size_t consumed_ = 0;
  uint32_t range_ = 0xFFFFFFFFu;
  uint32_t code_ = 0;
  uint32_t pending_r_ = 1;      // range / total from the last peekFrequency
  uint32_t pending_total_ = 1;  // total from the last peekFrequency
  bool overrun_ = false;
};

}  // namespace scanpress
