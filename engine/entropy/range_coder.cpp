#include "engine/entropy/range_coder.h"

#include <algorithm>
#include <cassert>
#include <cmath>

namespace scanpress {

// ---------------------------------------------------------------------------------------------- SymbolModel

SymbolModel::SymbolModel(uint32_t num_symbols)
    : n_(std::clamp<uint32_t>(num_symbols, 1, kMaxSymbols)),
      counts_(n_, 0),
      cum_(n_ + 1, 0),
      lookup_((1u << kLookupBits) + 1, 0) {
  assert(num_symbols >= 1 && num_symbols <= kMaxSymbols);
  update_cycle_ = until_update_ = std::min<uint32_t>(n_ + 6, 1024) / 2 + 1;
  rebuild();
  // Start from a uniform distribution (each symbol counted once).
}

void SymbolModel::rebuild() {
  if (total_ > kMaxTotal) {
    total_ = 0;
    for (auto& c : counts_) {
      c = (c + 1) >> 1;
      total_ += c;
    }
  }
  // Every symbol keeps a width of at least 1 out of 2^15; the rest is shared in proportion to the counts (plus a
  // base count of 1 each so unseen symbols stay codable), and rounding leftovers go to the largest symbol.
  const uint32_t kTotal = 1u << kTotalBits;
  const uint64_t spread = kTotal - n_;
  const uint64_t denom = uint64_t(total_) + n_;
  uint32_t sum = 0, largest = 0, largest_width = 0;
  std::vector<uint32_t> width(n_);
  for (uint32_t s = 0; s < n_; ++s) {
    width[s] = 1 + static_cast<uint32_t>(spread * (counts_[s] + 1) / denom);
    sum += width[s];
    if (width[s] > largest_width) largest_width = width[s], largest = s;
  }
  width[largest] += kTotal - sum;
  uint32_t c = 0;
  for (uint32_t s = 0; s < n_; ++s) {
    cum_[s] = c;
    c += width[s];
  }
  cum_[n_] = c;
  // lookup_[j] = first symbol whose interval reaches value j << shift.
  const uint32_t shift = kTotalBits - kLookupBits;
  uint32_t s = 0;
  for (uint32_t j = 0; j <= (1u << kLookupBits); ++j) {
    const uint32_t v = std::min(j << shift, kTotal - 1);
    while (cum_[s + 1] <= v) ++s;
    lookup_[j] = static_cast<uint16_t>(s);
  }
  update_cycle_ = std::min<uint32_t>(update_cycle_ * 5 / 4, 1024);
  until_update_ = update_cycle_;
}

uint32_t SymbolModel::findSymbol(uint32_t value) const {
  const uint32_t j = value >> (kTotalBits - kLookupBits);
  uint32_t lo = lookup_[j], hi = lookup_[j + 1] + 1;
  hi = std::min(hi, n_);
  while (hi - lo > 8) {  // binary search among the few candidates of this lookup bucket
    const uint32_t mid = (lo + hi) / 2;
    if (cum_[mid] <= value) lo = mid;
    else hi = mid;
  }
  while (cum_[lo + 1] <= value) ++lo;
  return lo;
}

// --------------------------------------------------------------------------------------------- RangeEncoder

void RangeEncoder::shiftLow() {
  if (static_cast<uint32_t>(low_) < 0xFF000000u || (low_ >> 32) != 0) {
    const uint8_t carry = static_cast<uint8_t>(low_ >> 32);
    uint8_t byte = cache_;
    do {
      if (first_) first_ = false;
      else out_.push_back(static_cast<uint8_t>(byte + carry));
      byte = 0xFF;
    } while (--pending_ != 0);
    cache_ = static_cast<uint8_t>(low_ >> 24);
  }
  ++pending_;
  low_ = (low_ & 0x00FFFFFFu) << 8;
}

void RangeEncoder::encodeBit(BitModel& model, int bit) {
  const uint32_t bound = (range_ >> 16) * model.p0();
  if (meter_) *meter_ -= std::log2((bit ? 65536.0 - model.p0() : double(model.p0())) / 65536.0);
  if (bit) {
    low_ += bound;
    range_ -= bound;
  } else {
    range_ = bound;
  }
  model.update(bit);
  normalize();
}

void RangeEncoder::encodeSymbol(SymbolModel& model, uint32_t symbol) {
  assert(symbol < model.n_);
  const uint32_t r = range_ >> SymbolModel::kTotalBits;
  const uint32_t lo = model.cum_[symbol];
  if (meter_) *meter_ -= std::log2(double(model.cum_[symbol + 1] - lo) / double(1u << SymbolModel::kTotalBits));
  low_ += uint64_t(r) * lo;
  if (symbol + 1 == model.n_) range_ -= r * lo;  // the last symbol takes the truncation remainder
  else range_ = r * (model.cum_[symbol + 1] - lo);
  model.record(symbol);
  normalize();
}

void RangeEncoder::encodeFrequency(uint32_t cum, uint32_t freq, uint32_t total) {
  assert(freq >= 1 && cum + freq <= total && total <= (1u << 16));
  const uint32_t r = range_ / total;
  if (meter_) *meter_ -= std::log2(double(freq) / double(total));
  low_ += uint64_t(r) * cum;
  if (cum + freq == total) range_ -= r * cum;
  else range_ = r * freq;
  normalize();
}

void RangeEncoder::encodeBits(uint32_t value, int bits) {
  assert(bits >= 0 && bits <= 32);
  if (meter_) *meter_ += bits;
  while (bits > 0) {
    const int n = bits > 16 ? 16 : bits;
    bits -= n;
    const uint32_t part = (value >> bits) & ((1u << n) - 1);
    range_ >>= n;
    low_ += uint64_t(range_) * part;
    normalize();
  }
}

void RangeEncoder::encodeUniform(uint32_t value, uint32_t count) {
  assert(value < count);
  if (count <= (1u << 16)) {
    if (count > 1) encodeFrequency(value, 1, count);
    return;
  }
  int bits = 0;
  while ((uint64_t(1) << bits) < count) ++bits;
  encodeBits(value, bits);
}

void RangeEncoder::finish() {
  for (int i = 0; i < 5; ++i) shiftLow();
}

// --------------------------------------------------------------------------------------------- RangeDecoder

RangeDecoder::RangeDecoder(std::span<const uint8_t> data) : data_(data) {
  for (int i = 0; i < 4; ++i) code_ = (code_ << 8) | nextByte();
}

int RangeDecoder::decodeBit(BitModel& model) {
  const uint32_t bound = (range_ >> 16) * model.p0();
  int bit;
  if (code_ < bound) {
    range_ = bound;
    bit = 0;
  } else {
    code_ -= bound;
    range_ -= bound;
    bit = 1;
  }
  model.update(bit);
  normalize();
  return bit;
}

uint32_t RangeDecoder::decodeSymbol(SymbolModel& model) {
  const uint32_t r = range_ >> SymbolModel::kTotalBits;
  uint32_t value = code_ / r;
  if (value >= (1u << SymbolModel::kTotalBits)) value = (1u << SymbolModel::kTotalBits) - 1;  // corrupt input
  const uint32_t symbol = model.findSymbol(value);
  const uint32_t lo = model.cum_[symbol];
  code_ -= r * lo;
  if (symbol + 1 == model.n_) range_ -= r * lo;
  else range_ = r * (model.cum_[symbol + 1] - lo);
  model.record(symbol);
  normalize();
  return symbol;
}

uint32_t RangeDecoder::peekFrequency(uint32_t total) {
  pending_total_ = total;
  pending_r_ = range_ / total;
  const uint32_t value = code_ / pending_r_;
  return value < total ? value : total - 1;
}

void RangeDecoder::consumeFrequency(uint32_t cum, uint32_t freq) {
  const uint32_t r = pending_r_;
  code_ -= r * cum;
  if (cum + freq == pending_total_) range_ -= r * cum;  // mirror of the encoder: last interval takes the rest
  else range_ = r * freq;
  normalize();
}

uint32_t RangeDecoder::decodeBits(int bits) {
  uint32_t value = 0;
  while (bits > 0) {
    const int n = bits > 16 ? 16 : bits;
    bits -= n;
    range_ >>= n;
    uint32_t part = code_ / range_;
    if (part >= (1u << n)) part = (1u << n) - 1;  // corrupt input
    code_ -= part * range_;
    value = (value << n) | part;
    normalize();
  }
  return value;
}

uint32_t RangeDecoder::decodeUniform(uint32_t count) {
  if (count <= 1) return 0;
  if (count <= (1u << 16)) {
    const uint32_t v = peekFrequency(count);
    consumeFrequency(v, 1);
    return v;
  }
  int bits = 0;
  while ((uint64_t(1) << bits) < count) ++bits;
  const uint32_t v = decodeBits(bits);
  return v < count ? v : count - 1;
}

}  // namespace scanpress
